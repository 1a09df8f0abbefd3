"""SPIDAR-G device model: presets, string geometry, pose estimation, tension distribution.

Pure numerics (numpy, scipy); no files except preset YAML, no MCAP, no CLI.  A replay uses

- per 1 kHz device tick: ``counts_from_pose`` (when synthesising from a scripted pose) and
  ``PoseEstimator.update(counts) -> (pos, quat)``, ``PoseEstimator.velocity``;
- per physics step (or tick): ``TensionDistributor.display(pos, quat, force, torque)``
  → tensions and the displayed wrench Aᵀt.

Frames, tables and the maths: docs/spidar.md.
"""

from puppetcli.spidar.errors import DeviceError
from puppetcli.spidar.estimator import EstimatorSettings, PoseEstimator, Track
from puppetcli.spidar.presetfile import (
    preset_from_option,
    preset_from_text,
    preset_from_yaml,
    preset_to_yaml,
)
from puppetcli.spidar.presets import DevicePreset, preset, preset_names
from puppetcli.spidar.strings import (
    StringState,
    check_reachable,
    counts_from_pose,
    lengths_from_counts,
    lengths_from_pose,
    strings_at,
    structure_matrix,
)
from puppetcli.spidar.tensions import (
    TensionDistributor,
    TensionResult,
    TensionWeights,
    capacity,
    motor_volts,
    solve_tensions,
)

__all__ = [
    "DeviceError",
    "DevicePreset",
    "EstimatorSettings",
    "PoseEstimator",
    "StringState",
    "TensionDistributor",
    "TensionResult",
    "TensionWeights",
    "Track",
    "capacity",
    "check_reachable",
    "counts_from_pose",
    "lengths_from_counts",
    "lengths_from_pose",
    "motor_volts",
    "preset",
    "preset_from_option",
    "preset_from_text",
    "preset_from_yaml",
    "preset_names",
    "preset_to_yaml",
    "solve_tensions",
    "strings_at",
    "structure_matrix",
]
