"""How a lab's capture maps onto the project's two hands: the mapping file of
``python -m mjx_hands.import_mocap`` (TOML), read and checked by :func:`load_mapping`.

Example (the skeleton ``export`` writes; ``mocap_data/README.md`` describes every key)::

    format = "bvh"            # "bvh" (a take is a folder of two skeleton files) or
                              # "motive" (a take is one OptiTrack Motive CSV export)
    length_unit = "cm"        # m | cm | mm; Motive: omit to use the file's Length Units
    fps = 120.0               # resample to this rate; omit to keep the capture's

    [contact]                 # the window Algorithm 1 searches for the closest approach
    margin = 0.01             # from the first frame within 1 cm of the palms' closest
                              # approach to the end of the take
    windows = { take01 = [130, 220] }   # or per take, in capture frames

    [actor]                   # the hand the robot learns to be; [target] alike
    file = "actor.bvh"        # BVH: the skeleton file in a take folder
    palm = "RightHand"        # BVH joint, Motive rigid body or bone carrying the palm
    palm_axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]  # rows: the project palm's x, y, z
                              # (thumb side, back of the hand, fingers) in that frame
    palm_centre = [0, 0, 0]   # the project's palm centre in that frame, file units

    [actor.joints]            # every one of the 20 HAND_JOINTS: a source or a constant
    FFJ2 = "RightHandIndex1.x"                      # BVH joint / Motive bone, Euler axis
    FFJ1 = { source = "RightHandIndex2.x", sign = 1, offset = 0.0 }
    THJ0 = 0.0                                      # not captured: radians

    [actor.bones]             # Motive only: each bone a joint reads, its parent bone and
    RightHandIndex1 = { parent = "RightHand", euler = "XZY" }   # Euler order

A joint's angle is ``sign * euler_component + offset`` (radians): for BVH the channel of
that axis, for Motive the component of the bone's rotation relative to its parent in the
bone's Euler order.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from mjx_hands.mocap.demonstration import MocapError
from mjx_hands.shadow_hand import HAND_JOINTS

FORMATS = ("bvh", "motive")
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""Metres per unit of each length unit a mapping may name."""
AXES = ("x", "y", "z")
HANDS = ("actor", "target")


@dataclasses.dataclass(frozen=True)
class JointSource:
    """Where one of the project's hand joints comes from: ``sign * angle + offset``.

    ``node`` None: the joint is the constant ``offset``."""

    node: str | None
    axis: str = "x"
    sign: float = 1.0
    offset: float = 0.0


@dataclasses.dataclass(frozen=True)
class Bone:
    """A Motive bone's parent bone and the Euler order of its rotation relative to it."""

    parent: str
    euler: str


@dataclasses.dataclass(frozen=True)
class HandMapping:
    """One hand of the mapping (see the module docstring)."""

    palm: str
    palm_axes: np.ndarray  # (3, 3) rows: project palm x, y, z in the capture's palm frame
    palm_centre: np.ndarray  # (3,) file units
    joints: dict[str, JointSource]  # every HAND_JOINTS name
    file: str | None = None
    bones: dict[str, Bone] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class Mapping:
    """A whole mapping file (see the module docstring)."""

    format: str
    actor: HandMapping
    target: HandMapping
    length_unit: str | None = None
    fps: float | None = None
    contact_margin: float = 0.01
    windows: dict[str, tuple[int, int]] = dataclasses.field(default_factory=dict)
    source: str = "<mapping>"


def _fail(where: str, key: str, message: str) -> MocapError:
    return MocapError(f"{where}: {key}: {message}")


def _number(where: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise _fail(where, key, f"expected a finite number, got {value!r}")
    return float(value)


def _vector(where: str, key: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise _fail(where, key, f"expected numbers of shape {shape}, got {value!r}") from None
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise _fail(where, key, f"expected finite numbers of shape {shape}, got {value!r}")
    return array


def _joint(where: str, key: str, value: Any) -> JointSource:
    if isinstance(value, int | float) and not isinstance(value, bool):
        return JointSource(None, offset=_number(where, key, value))
    if isinstance(value, str):
        value = {"source": value}
    if not isinstance(value, dict) or not isinstance(value.get("source"), str):
        raise _fail(
            where, key, f"expected 'NODE.AXIS', a table with 'source', or radians; got {value!r}"
        )
    unknown = set(value) - {"source", "sign", "offset"}
    if unknown:
        raise _fail(where, key, f"unknown keys {sorted(unknown)}; expected source, sign, offset")
    node, _, axis = value["source"].rpartition(".")
    if not node or axis.lower() not in AXES:
        raise _fail(
            where, key, f"source {value['source']!r} is not 'NODE.AXIS' with AXIS one of x, y, z"
        )
    return JointSource(
        node,
        axis.lower(),
        _number(where, f"{key}.sign", value.get("sign", 1.0)),
        _number(where, f"{key}.offset", value.get("offset", 0.0)),
    )


def _hand(where: str, table: Any, fmt: str) -> HandMapping:
    if not isinstance(table, dict):
        raise MocapError(f"{where}: expected a table")
    for key in ("palm", "joints"):
        if key not in table:
            raise _fail(where, key, "missing")
    unknown = set(table) - {"palm", "palm_axes", "palm_centre", "joints", "file", "bones"}
    if unknown:
        raise MocapError(f"{where}: unknown keys {sorted(unknown)}")
    axes = _vector(where, "palm_axes", table.get("palm_axes", np.eye(3)), (3, 3))
    if not np.allclose(axes @ axes.T, np.eye(3), atol=1e-6) or np.linalg.det(axes) < 0:
        raise _fail(where, "palm_axes", "expected a rotation (orthonormal rows, determinant +1)")
    joints = table["joints"]
    if not isinstance(joints, dict):
        raise _fail(where, "joints", "expected a table of HAND_JOINTS names")
    unknown = set(joints) - set(HAND_JOINTS)
    missing = [j for j in HAND_JOINTS if j not in joints]
    if unknown:
        raise _fail(where, "joints", f"unknown joints {sorted(unknown)}; expected {HAND_JOINTS}")
    if missing:
        raise _fail(where, "joints", f"missing {missing}: map each or give it a constant (radians)")
    parsed = {j: _joint(f"{where}.joints", j, joints[j]) for j in HAND_JOINTS}
    bones = {}
    for name, bone in table.get("bones", {}).items():
        if not isinstance(bone, dict) or set(bone) != {"parent", "euler"}:
            raise _fail(f"{where}.bones", name, f"expected {{parent, euler}}, got {bone!r}")
        order = str(bone["euler"]).upper()
        if sorted(order) != ["X", "Y", "Z"]:
            raise _fail(f"{where}.bones", name, f"euler {bone['euler']!r} is not an order of XYZ")
        bones[name] = Bone(str(bone["parent"]), order)
    if fmt == "motive":
        used = {s.node for s in parsed.values() if s.node is not None}
        lacking = sorted(used - set(bones))
        if lacking:
            raise _fail(where, "bones", f"{lacking} read by joints need a parent and Euler order")
    if fmt == "bvh" and not isinstance(table.get("file"), str):
        raise _fail(where, "file", "a BVH take is a folder: name the skeleton file of this hand")
    return HandMapping(
        palm=str(table["palm"]),
        palm_axes=axes,
        palm_centre=_vector(where, "palm_centre", table.get("palm_centre", [0, 0, 0]), (3,)),
        joints=parsed,
        file=table.get("file"),
        bones=bones,
    )


def parse_mapping(data: dict[str, Any], where: str = "<mapping>") -> Mapping:
    """A :class:`Mapping` from the parsed TOML ``data``; :class:`MocapError` naming the key
    for anything missing, unknown or out of range."""
    unknown = set(data) - {"format", "length_unit", "fps", "contact", "actor", "target"}
    if unknown:
        raise MocapError(f"{where}: unknown keys {sorted(unknown)}")
    fmt = data.get("format")
    if fmt not in FORMATS:
        raise _fail(where, "format", f"expected one of {FORMATS}, got {fmt!r}")
    unit = data.get("length_unit")
    if unit is None and fmt == "bvh":
        raise _fail(where, "length_unit", "BVH files carry no unit: give m, cm or mm")
    if unit is not None and unit not in LENGTH_UNITS:
        raise _fail(where, "length_unit", f"expected one of {tuple(LENGTH_UNITS)}, got {unit!r}")
    fps = data.get("fps")
    if fps is not None and _number(where, "fps", fps) <= 0:
        raise _fail(where, "fps", f"expected a positive rate, got {fps!r}")
    contact = data.get("contact", {})
    margin = _number(where, "contact.margin", contact.get("margin", 0.01))
    windows = {}
    for take, window in contact.get("windows", {}).items():
        if (
            not isinstance(window, list)
            or len(window) != 2
            or not all(isinstance(v, int) and v >= 0 for v in window)
            or window[0] > window[1]
        ):
            raise _fail(
                where, f"contact.windows.{take}", f"expected [begin, end] frames, got {window!r}"
            )
        windows[take] = (window[0], window[1])
    for hand in HANDS:
        if hand not in data:
            raise _fail(where, hand, "missing table")
    return Mapping(
        format=fmt,
        actor=_hand(f"{where}: actor", data["actor"], fmt),
        target=_hand(f"{where}: target", data["target"], fmt),
        length_unit=unit,
        fps=None if fps is None else float(fps),
        contact_margin=margin,
        windows=windows,
        source=where,
    )


def load_mapping(path: str | Path) -> Mapping:
    """Read and check a mapping file (see the module docstring)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise MocapError(f"mapping file {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise MocapError(f"{path}: not a TOML mapping file ({error})") from None
    return parse_mapping(data, str(path))


def _toml_key(key: str) -> str:
    return key if key and all(c.isalnum() or c in "_-" for c in key) else f'"{key}"'


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, dict):
        items = (f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items())
        return "{ " + ", ".join(items) + " }"
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(float(value)) if isinstance(value, float | np.floating) else str(value)


def mapping_toml(mapping: Mapping) -> str:
    """The TOML text of ``mapping`` (what :func:`load_mapping` reads back)."""
    lines = [f'format = "{mapping.format}"']
    if mapping.length_unit is not None:
        lines.append(f'length_unit = "{mapping.length_unit}"')
    if mapping.fps is not None:
        lines.append(f"fps = {mapping.fps!r}")
    lines += ["", "[contact]", f"margin = {mapping.contact_margin!r}"]
    if mapping.windows:
        windows = {k: list(v) for k, v in mapping.windows.items()}
        lines.append(f"windows = {_toml_value(windows)}")
    for name in HANDS:
        hand: HandMapping = getattr(mapping, name)
        lines += ["", f"[{name}]"]
        if hand.file is not None:
            lines.append(f'file = "{hand.file}"')
        lines.append(f'palm = "{hand.palm}"')
        lines.append(f"palm_axes = {_toml_value(hand.palm_axes.tolist())}")
        lines.append(f"palm_centre = {_toml_value(hand.palm_centre.tolist())}")
        lines += ["", f"[{name}.joints]"]
        for joint, source in hand.joints.items():
            if source.node is None:
                lines.append(f"{joint} = {source.offset!r}")
            elif source.sign == 1.0 and source.offset == 0.0:
                lines.append(f'{joint} = "{source.node}.{source.axis}"')
            else:
                table = {"source": f"{source.node}.{source.axis}", "sign": source.sign}
                lines.append(f"{joint} = {_toml_value(table | {'offset': source.offset})}")
        if hand.bones:
            lines += ["", f"[{name}.bones]"]
            for bone, info in hand.bones.items():
                table = {"parent": info.parent, "euler": info.euler}
                lines.append(f"{_toml_key(bone)} = {_toml_value(table)}")
    return "\n".join(lines) + "\n"
