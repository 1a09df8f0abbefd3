"""The input kinds of the fuzz: for each, a seeded mutant written into a work folder and the
command line that reads it.

``Seeds.make(folder)`` writes the valid inputs once (a small script on the doll, the outputs of
its pose: keyframes.json, keyframes.bvh, trace.mcap; its recorded session); each kind's
``case(seeds, rng, folder)`` returns the argv of one run on one mutant."""

from __future__ import annotations

import json
import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from fuzz_mutate import expand_deep, mutate_bytes, mutate_tree
from mcap.reader import make_reader
from mcap.writer import Writer

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"

# A short script that uses every kind of action, so a mutant reaches every part of the reader.
SCRIPT = """\
pointer: {start: [0.70, 1.36, 0.0], radius: 0.02}
haptics: {max_force: 20, max_torque: 1.0, lowpass: 0.2}
actions:
  - key: rest
  - grip: {bone: forearm_l, point: [0.24, 0.0, 0.0], position_only: true, stiffness: 2000}
  - move: {by: [0.0, 0.05, 0.0], duration: 0.1}
  - rotate: {axis: [0, 0, 1], angle: 10, duration: 0.05}
  - key: raised
  - release:
  - push: {bone: hips, force: [0, 0, 1.0], point: [0, 0, 0], duration: 0.05}
  - touch: {by: [0.0, 0.0, 0.05], duration: 0.05}
  - wait: 0.05
  - key: held
  - expect: {joint: forearm_l, min_angle: 0}
  - expect: {bone: hand_l, head: [0.8, 1.4, 0.0], tolerance: 5.0}
"""


@dataclass
class Seeds:
    """The valid inputs every mutant starts from."""

    rig: Path
    script: Path
    keys: Path
    bvh: Path
    trace: Path
    session: Path
    glb: Path

    @classmethod
    def make(cls, folder: Path, run) -> Seeds:
        """Write the script, pose it and record it with ``run`` (the harness's ``run_cli``)."""
        script = folder / "seed.yaml"
        script.write_text(SCRIPT)
        out, session = folder / "seed-out", folder / "seed.mcap"
        for args in (
            ["pose", str(DOLL), str(script), "-o", str(out), "--force", "--gltf"],
            ["record", str(DOLL), str(script), "-o", str(session), "--force"],
        ):
            outcome = run(args)
            assert outcome.code == 0, (args, outcome.stderr, outcome.exception)
        return cls(
            DOLL, script, out / "keyframes.json", out / "keyframes.bvh", out / "trace.mcap",
            session, out / "keyframes.glb",
        )  # fmt: skip


# Every output a case may write, planted before the run: a failed run must leave them as they were.
OUTPUTS = (
    "out/keyframes.json", "out/keyframes.bvh", "out/trace.mcap", "out/sheet.png",
    "out/keys/000.png", "o.bvh", "s.mcap", "s.png", "v.avi", "r.yaml",
)  # fmt: skip


def plant_outputs(folder: Path) -> None:
    """Write a sentinel into every output path of a case's folder."""
    for name in OUTPUTS:
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(f"sentinel {name}".encode())


def changed_outputs(folder: Path) -> list[str]:
    """The planted outputs that a run replaced, changed or removed."""
    return [
        name for name in OUTPUTS
        if not (folder / name).is_file()
        or (folder / name).read_bytes() != f"sentinel {name}".encode()
    ]  # fmt: skip


def _pick(rng: np.random.Generator, options: list):
    return options[int(rng.integers(len(options)))]


def _tree_or_bytes(text: bytes, rng: np.random.Generator, load, dump) -> bytes:
    """A mutant of a YAML or JSON file: a node of its tree (3 in 4) or its bytes."""
    if rng.random() < 0.75:
        return expand_deep(dump(mutate_tree(load(text), rng))).encode()
    return mutate_bytes(text, rng)


def _yaml_mutant(path: Path, rng: np.random.Generator) -> bytes:
    return _tree_or_bytes(path.read_bytes(), rng, yaml.safe_load, yaml.safe_dump)


def _json_mutant(path: Path, rng: np.random.Generator) -> bytes:
    return _tree_or_bytes(path.read_bytes(), rng, json.loads, json.dumps)


def _write(folder: Path, name: str, data: bytes) -> Path:
    path = folder / name
    path.write_bytes(data)
    return path


def rig_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    rig = _write(folder, "rig.yaml", _yaml_mutant(seeds.rig, rng))
    if rng.random() < 0.3:
        return ["validate", str(rig)]
    return ["pose", str(rig), str(seeds.script), "-o", str(folder / "out"), "--force"]


def script_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    script = _write(folder, "script.yaml", _yaml_mutant(seeds.script, rng))
    command = _pick(rng, ["pose", "pose", "convert", "record"])
    if command == "pose":
        return ["pose", str(seeds.rig), str(script), "-o", str(folder / "out"), "--force"]
    if command == "convert":
        return ["convert", str(script), "--rig", str(seeds.rig), "-o", str(folder / "o.bvh"),
                "--force"]  # fmt: skip
    return ["record", str(seeds.rig), str(script), "-o", str(folder / "s.mcap"), "--force"]


def mcap_messages(path: Path) -> tuple[list, list]:
    """The metadata records and the (topic, schema name, log time, message dict) of a file."""
    with path.open("rb") as stream:
        reader = make_reader(stream)
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        stream.seek(0)
        messages = [
            (channel.topic, schema.name, message.log_time, json.loads(message.data))
            for schema, channel, message in make_reader(stream).iter_messages()
        ]
    return metadata, messages


def write_mcap(path: Path, metadata: list, messages: list) -> None:
    """An MCAP file of JSON channels with these metadata records and (topic, schema name, log
    time, message) messages; a ``deep`` marker in a message is written as nested brackets."""
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="fuzz")
        schemas, channels = {}, {}
        for topic, schema, _, _ in messages:
            if topic not in channels:
                if schema not in schemas:
                    schemas[schema] = writer.register_schema(schema, "jsonschema", b"{}")
                channels[topic] = writer.register_channel(topic, "json", schemas[schema])
        for name, values in metadata:
            writer.add_metadata(name, values)
        for topic, _, log_time, data in messages:
            text = expand_deep(json.dumps(data)).encode()
            writer.add_message(channels[topic], int(log_time), text, int(log_time))
        writer.finish()


def _mcap_mutant(path: Path, rng: np.random.Generator, out: Path) -> None:
    """One message, one metadata value or the bytes of an MCAP file changed."""
    if rng.random() < 0.3:
        out.write_bytes(mutate_bytes(path.read_bytes(), rng))
        return
    metadata, messages = mcap_messages(path)
    if rng.random() < 0.3 and metadata:
        _, values = _pick(rng, metadata)
        key = _pick(rng, sorted(values))
        try:
            tree = json.loads(values[key])
        except ValueError:
            tree = values[key]
        mutated = mutate_tree(tree, rng)
        values[key] = expand_deep(mutated if isinstance(mutated, str) else json.dumps(mutated))
    else:
        index = int(rng.integers(len(messages)))
        topic, schema, log_time, data = messages[index]
        if rng.random() < 0.2:
            log_time = _pick(rng, [0, 2**63 - 1, 10**18, log_time * 1000])
            data["t"] = log_time / 1e9
        messages[index] = (topic, schema, log_time, mutate_tree(data, rng))
    write_mcap(out, metadata, messages)


def session_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    session = folder / "session.mcap"
    _mcap_mutant(seeds.session, rng, session)
    if rng.random() < 0.3:
        return ["convert", str(session), "--rig", str(seeds.rig), "-o", str(folder / "o.bvh"),
                "--force"]  # fmt: skip
    return ["pose", str(seeds.rig), str(session), "-o", str(folder / "out"), "--force",
            "--no-render"]  # fmt: skip


def trace_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    trace = folder / "trace.mcap"
    _mcap_mutant(seeds.trace, rng, trace)
    if rng.random() < 0.3:
        return ["render", str(trace), "--rig", str(seeds.rig), "--video",
                str(folder / "v.avi"), "--size", "64x64", "--force"]  # fmt: skip
    return ["render", str(trace), "--rig", str(seeds.rig), "-o", str(folder / "s.png"),
            "--size", "64x64", "--force"]  # fmt: skip


def _bvh_mutant(path: Path, rng: np.random.Generator) -> bytes:
    text = path.read_bytes()
    op = int(rng.integers(4))
    if op == 0:  # a huge declared frame count
        count = _pick(rng, [b"999999999999", b"4294967297", b"100000000", b"1e9", b"-5", b""])
        return re.sub(rb"Frames:[ \t]*\d+", b"Frames: " + count, text, count=1)
    if op == 1:  # a deep hierarchy
        levels = int(rng.integers(200, 20000))
        body = b"".join(b"JOINT j%d\n{\nOFFSET 0 0.01 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
                        % i for i in range(levels))  # fmt: skip
        return (b"HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
                b"Zrotation Xrotation Yrotation\n" + body + b"End Site\n{\nOFFSET 0 0.01 0\n}\n"
                + b"}\n" * (levels + 1) + b"MOTION\nFrames: 1\nFrame Time: 0.03\n"
                + b"0 " * (6 + 3 * levels) + b"\n")  # fmt: skip
    return mutate_bytes(text, rng)


def bvh_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    bvh = _write(folder, "in.bvh", _bvh_mutant(seeds.bvh, rng))
    if rng.random() < 0.5:
        return ["rig", "from-bvh", str(bvh), "-o", str(folder / "r.yaml"), "--force"]
    return ["render", str(bvh), "--rig", str(seeds.rig), "-o", str(folder / "s.png"),
            "--size", "64x64", "--force"]  # fmt: skip


def _glb_mutant(path: Path, rng: np.random.Generator) -> bytes:
    """A glb with its JSON chunk's tree mutated (3 in 4), or its bytes."""
    data = path.read_bytes()
    if rng.random() >= 0.75:
        return mutate_bytes(data, rng)
    (size,) = struct.unpack_from("<I", data, 12)
    doc = json.dumps(mutate_tree(json.loads(data[20 : 20 + size]), rng)).encode()
    doc += b" " * (-len(doc) % 4)
    body = struct.pack("<I4s", len(doc), b"JSON") + doc + data[20 + size :]
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def gltf_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    glb = _write(folder, "in.glb", _glb_mutant(seeds.glb, rng))
    pick = rng.random()
    if pick < 0.4:
        return ["rig", "from-gltf", str(glb), "-o", str(folder / "r.yaml"), "--force"]
    rig = ["--rig", str(seeds.rig)] if pick < 0.7 else []
    return ["render", str(glb), *rig, "-o", str(folder / "s.png"), "--size", "64x64", "--force"]


def keys_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    keys = _write(folder, "keyframes.json", _json_mutant(seeds.keys, rng))
    return ["render", str(keys), "--rig", str(seeds.rig), "-o", str(folder / "s.png"),
            "--size", "64x64", "--force"]  # fmt: skip


def preset_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    from puppetcli.spidar.presetfile import preset_to_yaml
    from puppetcli.spidar.presets import preset

    base = folder / "preset-base.yaml"
    base.write_text(preset_to_yaml(preset("SpidarG6X3R")))
    preset = _write(folder, "preset.yaml", _yaml_mutant(base, rng))
    return ["record", str(seeds.rig), str(seeds.script), "-o", str(folder / "s.mcap"),
            "--device", str(preset), "--force"]  # fmt: skip


OPTION_VALUES = [
    "0", "-1", "1e-7", "1e-300", "inf", "-inf", "nan", "1e6", "1e308", "abc", "", "9" * 40,
    "0x0", "1x1", "100000x100000", "custom:", "custom:nan,0", "custom:0,0,0", "custom:1e9,1e9",
    "custom:0,90", "custom:0,0,inf", "iso", "XYZ", "zxy", "Zxy", "\x00", "a\nb", "1,2",
]  # fmt: skip

OPTIONS = {
    "pose": ["--h", "--fps", "--scale", "--view", "--order", "--trace-every", "--interpolate"],
    "convert": ["--fps", "--scale", "--order"],
    "render": ["--cols", "--view", "--size", "--fps"],
    "record": ["--noise", "--seed", "--device"],
}


def option_case(seeds: Seeds, rng: np.random.Generator, folder: Path) -> list[str]:
    command = _pick(rng, sorted(OPTIONS))
    chosen = rng.choice(OPTIONS[command], size=int(rng.integers(1, 3)), replace=False)
    extra = []
    for option in chosen:
        extra += [str(option), _pick(rng, OPTION_VALUES)]
    if command == "pose":
        base = ["pose", str(seeds.rig), str(seeds.script), "-o", str(folder / "out"), "--force"]
        if "--fps" not in chosen and rng.random() < 0.5:
            extra += ["--interpolate", "slerp"]
    elif command == "convert":
        base = ["convert", str(seeds.script), "--rig", str(seeds.rig), "-o",
                str(folder / "o.bvh"), "--force"]  # fmt: skip
    elif command == "render":
        source = _pick(rng, [seeds.keys, seeds.trace])
        video = ["--video", str(folder / "v.avi")] if source == seeds.trace else []
        base = ["render", str(source), "--rig", str(seeds.rig), "-o", str(folder / "s.png"),
                "--force", *video]  # fmt: skip
    else:
        base = ["record", str(seeds.rig), str(seeds.script), "-o", str(folder / "s.mcap"),
                "--force"]  # fmt: skip
    return base + extra


KINDS = {
    "rig": rig_case,
    "script": script_case,
    "session": session_case,
    "trace": trace_case,
    "bvh": bvh_case,
    "gltf": gltf_case,
    "keys": keys_case,
    "preset": preset_case,
    "option": option_case,
}
