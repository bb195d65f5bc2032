"""The rig's four messages of a tick serialized (CDR) from templates, without rclpy message objects."""

from __future__ import annotations

import struct
from dataclasses import fields
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message

from g2p.bags.interfaces import InterfaceLibrary, TypeRegistry, ament_share_dirs
from g2p.plant import N_JOINTS, N_MOTORS, TickSample
from g2p_ros.convert import tick_messages

# TickSample's numeric fields, in the order TickSerializer takes their values.
_TICK_FIELDS = tuple(f.name for f in fields(TickSample) if f.name != "t_s")
# Stamp sentinels (int32 sec, uint32 nanosec) for the templates; their bytes appear nowhere else.
_SENTINEL_SEC, _SENTINEL_NANOSEC = 0x5A5A5A01, 0x5A5A5A02
_STAMP = struct.Struct("<iI")
_FLOAT64 = struct.Struct("<d")


class TickSerializer:
    """The four messages of `tick_messages`, serialized (CDR), without building rclpy message objects.

    Building the four messages costs about 40 us per tick (rclpy's field setters check every value) with
    the GIL held, which in fast simulation limits the rig (docs/RESULTS.md). Every per-tick field has a
    fixed size (two joints, three motors, a constant frame_id), so each message's serialized form is a
    template with the tick's numbers at fixed offsets. The templates are `tick_messages` for a sample whose
    every number is a distinct sentinel, serialized by rclpy and normalized by rosbags (`_canonical`); each
    sentinel's position is where its value goes.

    Raises:
        ValueError: (at construction) a sentinel is not found exactly once, i.e. the layout is not fixed.
    """

    def __init__(self) -> None:
        sentinels = iter(float(k) * 1e300 for k in range(1, 100))

        def row(n: int) -> np.ndarray:
            return np.array([next(sentinels) for _ in range(n)])

        sample = TickSample(
            t_s=0.0,
            activation=row(N_MOTORS),
            position_rad=row(N_JOINTS),
            velocity_rad_s=row(N_JOINTS),
            belt_mm=next(sentinels),
            belt_velocity_mm_s=next(sentinels),
            current_a=row(N_MOTORS),
            power_w=row(N_MOTORS),
            energy_j=row(N_MOTORS),
        )
        flat = _flatten(sample)
        stamp = Time(sec=_SENTINEL_SEC, nanosec=_SENTINEL_NANOSEC)
        types = TypeRegistry(InterfaceLibrary(ament_share_dirs()))
        self._templates: list[tuple[bytes, int, list[tuple[int, int]]]] = []
        for msg in tick_messages(sample, stamp):
            data = _canonical(msg, types)
            if data[:2] != b"\x00\x01":  # CDR encapsulation: plain, little endian
                raise ValueError(f"{type(msg).__name__}: expected little-endian CDR, got {data[:2].hex()}")
            stamp_at = _find_once(data, _STAMP.pack(_SENTINEL_SEC, _SENTINEL_NANOSEC), type(msg).__name__)
            slots = [
                (i, at)
                for i, value in enumerate(flat)
                if (at := _find_once(data, _FLOAT64.pack(value), type(msg).__name__, required=False)) >= 0
            ]
            self._templates.append((data, stamp_at, slots))

    def serialize(self, sample: TickSample, stamp_ns: int) -> list[bytes]:
        """The serialized JointState, Treadmill, MotorPower and MotorActivation of one tick.

        Args:
            sample: the tick.
            stamp_ns: the header stamp (ns), as `stamp_ns` rounds it.
        """
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        flat = _flatten(sample)
        out = []
        for data, stamp_at, slots in self._templates:
            buf = bytearray(data)
            _STAMP.pack_into(buf, stamp_at, sec, nanosec)
            for i, at in slots:
                _FLOAT64.pack_into(buf, at, flat[i])
            out.append(bytes(buf))
        return out


def _canonical(msg: Any, types: TypeRegistry) -> bytes:
    """`msg` serialized as DDS sends it and rosbags reads it: exact length, zero padding.

    rclpy's serialize_message returns rmw's estimated size, which may exceed the message (rosbags rejects
    the extra bytes), and leaves alignment padding uninitialized. The longest prefix rosbags accepts is the
    message; rosbags serializes it again with zero padding.
    """
    data = serialize_message(msg)
    name = f"{type(msg).__module__.split('.')[0]}/msg/{type(msg).__name__}"
    types.register(name)
    for end in range(len(data), 3, -1):
        out = types.reserialize(data[:end], name)
        if out is not None and deserialize_message(out, type(msg)) == msg:
            return out
    raise ValueError(f"{name}: rosbags does not read rclpy's serialization of the message")


def _flatten(sample: TickSample) -> list[float]:
    return np.hstack([getattr(sample, name) for name in _TICK_FIELDS]).tolist()


def _find_once(data: bytes, pattern: bytes, what: str, required: bool = True) -> int:
    at = data.find(pattern)
    if (at < 0 and required) or (at >= 0 and data.find(pattern, at + 1) >= 0):
        raise ValueError(f"{what}: a field's sentinel is not found exactly once: the layout is not fixed")
    return at
