"""OptiTrack Motive CSV takes (no maintained PyPI reader exists, so a small parser).

Format: Motive's CSV export, format version 1.2x (tested: 1.23, written by Motive 2.x
and 3.x with "Rotation Type: Quaternion" and "Coordinate Space: Global")::

    Format Version,1.23,Take Name,take01,...,Export Frame Rate,120.000000,...,
        Rotation Type,Quaternion,Length Units,Meters,Coordinate Space,Global
    <blank>
    ,Type,Bone,Bone,...                  (or Rigid Body; marker columns are ignored)
    ,Name,Actor:RightHand,Actor:RightHand,...
    ,ID,1,1,...
    ,,Rotation,Rotation,Rotation,Rotation,Position,Position,Position,...
    Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,...
    0,0.000000,...

A take is one such file; the mapping names the palm bodies (rigid bodies or bones) and,
for each bone a joint reads, its parent and Euler order (``mapping``). Blank cells
(occlusions) are an error naming the body and frame: fill gaps in Motive first.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from mjx_hands.mocap import skeleton
from mjx_hands.mocap.capture import HandTrack, Take, mapped_joints, palm_track
from mjx_hands.mocap.demonstration import Demonstration, MocapError, quat_xyzw_to_matrix
from mjx_hands.mocap.mapping import LENGTH_UNITS, HandMapping, Mapping

FORMAT_VERSIONS = ("1.2", "1.21", "1.22", "1.23", "1.24", "1.25")
"""Versions of the CSV layout this reads (the layout above)."""
UNITS = {"Meters": "m", "Centimeters": "cm", "Millimeters": "mm"}
HEADER_ROWS = 7


def _header(path: Path, rows: list[list[str]]) -> dict[str, str]:
    if len(rows) < HEADER_ROWS + 2:
        raise MocapError(
            f"{path}: not a Motive CSV take (expected {HEADER_ROWS} header rows and at least "
            f"2 frames, got {len(rows)} rows)"
        )
    first = rows[0]
    info = {first[i].strip(): first[i + 1].strip() for i in range(0, len(first) - 1, 2)}
    version = info.get("Format Version")
    if version not in FORMAT_VERSIONS:
        raise MocapError(
            f"{path}: Format Version {version!r} is not one this reads (expected one of "
            f"{', '.join(FORMAT_VERSIONS)}); export the take as CSV from Motive"
        )
    for key, expected in (("Rotation Type", "Quaternion"), ("Coordinate Space", "Global")):
        if info.get(key, expected) != expected:
            raise MocapError(f"{path}: {key} is {info[key]!r}; export with {key} {expected!r}")
    labels = [r[:2] for r in rows[2:HEADER_ROWS]]
    if [x[1].strip() if len(x) > 1 else "" for x in labels[:3]] != ["Type", "Name", "ID"] or (
        rows[HEADER_ROWS - 1][:2] != ["Frame", "Time (Seconds)"]
    ):
        raise MocapError(
            f"{path}: rows 3-7 must be the Type, Name, ID, kind and 'Frame,Time (Seconds),X,...' "
            "header of a Motive CSV export"
        )
    return info


def read_bodies(path: str | Path) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], float, str]:
    """Every rigid body's and bone's pose in a Motive CSV take.

    Returns:
      {name: (rotation (T, 3, 3), position (T, 3) file units)}, the frame rate (Hz) and
      the file's length unit ("m", "cm", "mm" or "" when not stated).
    """
    path = Path(path)
    if not path.is_file():
        raise MocapError(f"Motive CSV take {path} does not exist")
    try:
        with path.open(newline="") as file:
            rows = list(csv.reader(file))
    except (UnicodeDecodeError, csv.Error) as error:
        raise MocapError(f"{path}: not a Motive CSV file ({error})") from None
    info = _header(path, rows)
    try:
        fps = float(info.get("Export Frame Rate", info.get("Capture Frame Rate", "")))
    except ValueError:
        fps = float("nan")
    if not fps > 0:
        raise MocapError(f"{path}: Export Frame Rate must be a positive number")
    unit = UNITS.get(info.get("Length Units", ""), "")
    types, names, _, kinds, axes = rows[2:HEADER_ROWS]
    columns: dict[str, dict[str, int]] = {}
    for c in range(2, len(axes)):
        kind = kinds[c] if c < len(kinds) else ""
        body_type = types[c] if c < len(types) else ""
        if kind in ("Rotation", "Position") and body_type in ("Rigid Body", "Bone"):
            key = ("q" if kind == "Rotation" else "p") + axes[c].strip().lower()
            columns.setdefault(names[c], {})[key] = c
    data = rows[HEADER_ROWS:]
    while data and not any(cell.strip() for cell in data[-1]):
        data.pop()
    width = max(max(cols.values()) for cols in columns.values()) + 1 if columns else 0
    bodies = {}
    for name, cols in columns.items():
        wanted = ("qx", "qy", "qz", "qw", "px", "py", "pz")
        if set(cols) != set(wanted):
            raise MocapError(f"{path}: {name} lacks columns {sorted(set(wanted) - set(cols))}")
        values = np.full((len(data), 7), np.nan)
        for t, row in enumerate(data):
            if len(row) < width:
                raise MocapError(f"{path}: frame row {t} has {len(row)} cells, expected {width}")
            for k, key in enumerate(wanted):
                cell = row[cols[key]].strip()
                if cell:
                    try:
                        values[t, k] = float(cell)
                    except ValueError:
                        raise MocapError(
                            f"{path}: {name} {key} at frame row {t} is {cell!r}, not a number"
                        ) from None
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            raise MocapError(
                f"{path}: {name} is missing (occluded) from frame row {int(np.argmax(bad))} "
                f"({int(bad.sum())} frames in all); fill the gaps in Motive before export"
            )
        norm = np.linalg.norm(values[:, :4], axis=-1)
        if np.any(np.abs(norm - 1.0) > 0.1):
            t = int(np.argmax(np.abs(norm - 1.0) > 0.1))
            raise MocapError(
                f"{path}: {name} rotation at frame row {t} is not a unit quaternion "
                f"(norm {norm[t]:.3g}, expected 1 +- 0.1)"
            )
        bodies[name] = (quat_xyzw_to_matrix(values[:, :4]), values[:, 4:])
    return bodies, fps, unit


def _hand(path: Path, bodies: dict, hand: HandMapping, metres: float, frames: int) -> HandTrack:
    def body(name: str, role: str):
        if name not in bodies:
            raise MocapError(
                f"{path}: no rigid body or bone {name!r} ({role}); it has {sorted(bodies)}"
            )
        return bodies[name]

    rot, pos = body(hand.palm, "the mapping's palm")
    palm_pos, palm_rot = palm_track(rot, pos, hand, metres)
    angle_of = {}
    for name, bone in hand.bones.items():
        child, _ = body(name, "a mapped bone")
        parent, _ = body(bone.parent, f"the parent of {name}")
        relative = np.swapaxes(parent, -1, -2) @ child
        angles = skeleton.euler_angles(relative, bone.euler)
        angle_of[name] = skeleton.euler_by_axis(angles, bone.euler)
    return HandTrack(palm_pos, palm_rot, mapped_joints(str(path), hand, angle_of, frames))


def read_take(file: str | Path, mapping: Mapping) -> Take:
    """The take in the Motive CSV ``file``; MocapError naming the file for anything
    unreadable, unmapped or inconsistent."""
    file = Path(file)
    bodies, fps, unit = read_bodies(file)
    unit = mapping.length_unit or unit
    if unit not in LENGTH_UNITS:
        raise MocapError(
            f"{file}: the file states no Length Units; give length_unit in the mapping"
        )
    frames = len(next(iter(bodies.values()))[1]) if bodies else 0
    actor = _hand(file, bodies, mapping.actor, LENGTH_UNITS[unit], frames)
    target = _hand(file, bodies, mapping.target, LENGTH_UNITS[unit], frames)
    return Take(file.stem, fps, actor, target)


def write_take(demo: Demonstration, file: str | Path, take: str | None = None) -> Path:
    """``demo`` as a Motive CSV take of the project's skeleton (bones ``Actor:<node>`` and
    ``Target:<node>``, metres, quaternions, global): the target palm at the origin."""
    file = Path(file)
    file.parent.mkdir(parents=True, exist_ok=True)
    frames = demo.num_frames
    identity = np.broadcast_to(np.eye(3), (frames, 3, 3))
    hands = {
        "actor": skeleton.world_poses(
            demo.actor_joints, demo.actor_points[:, 0], demo.actor_palm_rot
        ),
        "target": skeleton.world_poses(demo.target_joints, np.zeros((frames, 3)), identity),
    }
    from mjx_hands.mocap.demonstration import matrix_to_quat_wxyz

    header = [[], [], [], [], []]  # Type, Name, ID, kind, axis
    columns = []
    for which, poses in hands.items():
        for k, (node, (pos, rot)) in enumerate(poses.items()):
            name = f"{skeleton.MOTIVE_SKELETONS[which]}:{node}"
            q = matrix_to_quat_wxyz(rot)[:, [1, 2, 3, 0]]  # x, y, z, w
            columns.append(np.concatenate([q, pos], -1))
            header[0] += ["Bone"] * 7
            header[1] += [name] * 7
            header[2] += [str(k + 1)] * 7
            header[3] += ["Rotation"] * 4 + ["Position"] * 3
            header[4] += ["X", "Y", "Z", "W", "X", "Y", "Z"]
    values = np.concatenate(columns, -1)
    info = [
        "Format Version", "1.23", "Take Name", take or file.stem, "Take Notes", "",
        "Capture Frame Rate", f"{demo.fps:.6f}", "Export Frame Rate", f"{demo.fps:.6f}",
        "Total Frames in Take", str(frames), "Total Exported Frames", str(frames),
        "Rotation Type", "Quaternion", "Length Units", "Meters", "Coordinate Space", "Global",
    ]  # fmt: skip
    with file.open("w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(info)
        writer.writerow([])
        for label, row in zip(("Type", "Name", "ID"), header[:3]):
            writer.writerow(["", label] + row)
        writer.writerow(["", ""] + header[3])
        writer.writerow(["Frame", "Time (Seconds)"] + header[4])
        for t in range(frames):
            writer.writerow([str(t), f"{t / demo.fps:.6f}"] + [f"{v:.9f}" for v in values[t]])
    return file
