"""A video of a whole trace with OpenCV's VideoWriter: ``.mp4`` (mp4v) or ``.avi`` (MJPG).

Frames are taken at a fixed rate of *simulated* time: frame k shows the last
recorded step at or before t0 + k / fps, so the video plays in real time
whatever the trace's step.  H.264 is avoided because pip wheels of OpenCV
usually lack its encoder.  The file is written under a temporary name with the
same suffix (OpenCV picks the container from it) and renamed when complete.
"""

from __future__ import annotations

import bisect
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np

from puppetcli.errors import shown
from puppetcli.render.camera import RenderError
from puppetcli.render.picture import Framing, Pose, render_pose
from puppetcli.rig.skeleton import Skeleton
from solver.spec import RigSpec

__all__ = ["CODECS", "frame_count", "frame_indices", "write_video"]

CODECS = {".mp4": "mp4v", ".avi": "MJPG"}


def frame_count(times: Sequence[float], fps: float) -> int:
    """Frames of a video at ``fps`` from the first to the last of ``times`` (0 if none)."""
    if not times:
        return 0
    return int(np.floor((times[-1] - times[0]) * fps + 1e-9)) + 1


def frame_indices(times: Sequence[float], fps: float) -> list[int]:
    """Index of the step shown in each video frame: the last step at or before t0 + k/fps."""
    n = frame_count(times, fps)
    return [max(0, bisect.bisect_right(times, times[0] + k / fps + 1e-12) - 1) for k in range(n)]


def write_video(
    path: Path,
    skel: Skeleton,
    poses: Sequence[Pose],
    spec: RigSpec,
    framing: Framing,
    fps: float,
    on_frame: Callable[[], None] | None = None,
) -> int:
    """Encode ``poses`` at ``fps`` frames per simulated second; returns the frame count."""
    path = Path(path)
    codec = CODECS.get(path.suffix.lower())
    if codec is None:
        raise RenderError(f"--video: expected an .mp4 or .avi file name, got {shown(path.name)}")
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*codec), fps, framing.camera.size)
    try:
        if not writer.isOpened():
            raise RenderError(
                f"{path}: cannot encode video: this OpenCV build has no {codec} encoder "
                f"for {path.suffix} (try the other of .mp4 / .avi)"
            )
        indices = frame_indices([p.time for p in poses], fps)
        for i in indices:
            writer.write(render_pose(skel, poses[i], spec, framing))
            if on_frame is not None:
                on_frame()
        writer.release()
        if not tmp.exists() or tmp.stat().st_size == 0:
            raise RenderError(f"{path}: the {codec} encoder wrote nothing")
        os.replace(tmp, path)
    except OSError as exc:
        raise RenderError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        writer.release()
        tmp.unlink(missing_ok=True)
    return len(indices)
