"""The leg's calibration file, read without the simulator: its format, and the packaged calibrations.

A calibration file (`g2p-calibrate` writes it; docs/SIMULATOR.md, "Calibration") is a small versioned YAML
document whose `parameters` map physical parameters, named with their units, to values. The simulator
writes them into its MuJoCo model (g2p.sim.calibration, which also checks each value's range); the rig's
safety envelope takes its motor, tendon and winding constants from them (g2p.rig.envelope), on the Pi as
in the simulator. Reading one needs only YAML.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml

FORMAT = "g2p-leg-calibration"
VERSION = 1
MODEL_NAME = "g2p_leg"


class CalibrationError(ValueError):
    """A calibration file cannot be read or holds invalid values; the message names the file or field."""


def _packaged_dir() -> Path:
    return Path(str(resources.files("g2p.description").joinpath("models", "calibrations")))


def packaged_calibrations() -> list[str]:
    """Names of the calibrations shipped in g2p/description/models/calibrations/."""
    return sorted(p.stem for p in _packaged_dir().glob("*.yaml"))


def resolve_calibration_path(name_or_path: str) -> Path:
    """The file a `calibration` setting names: a path, or the name of a packaged calibration.

    Raises:
        CalibrationError: neither a file nor a packaged calibration.
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    packaged = _packaged_dir() / f"{name_or_path}.yaml"
    if "/" not in name_or_path and packaged.is_file():
        return packaged
    raise CalibrationError(
        f"no calibration file {name_or_path!r} (nor a packaged one: {', '.join(packaged_calibrations())})"
    )


def check_document(doc: Any, where: str) -> dict[str, Any]:
    """The `parameters` of a calibration document, once its format, version and model are checked.

    Args:
        doc: the parsed YAML document.
        where: what to name in an error (the file).

    Raises:
        CalibrationError: wrong format, version or model, or `parameters` not a mapping.
    """
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CalibrationError(f"{where}: not a leg calibration (needs 'format: {FORMAT}')")
    if doc.get("version") != VERSION:
        raise CalibrationError(
            f"{where}: version {doc.get('version')!r} is not supported (this reads {VERSION})"
        )
    if doc.get("model") != MODEL_NAME:
        raise CalibrationError(f"{where}: calibrates model {doc.get('model')!r}, not {MODEL_NAME!r}")
    parameters = doc.get("parameters") or {}
    if not isinstance(parameters, dict):
        raise CalibrationError(f"{where}: 'parameters' must be a mapping of name to value")
    return dict(parameters)


def read_document(name_or_path: str) -> tuple[dict[str, Any], str]:
    """A calibration file's checked document (`check_document`) and the path it was read from.

    Raises:
        CalibrationError: the file is missing, is not YAML, or is not a leg calibration.
    """
    path = resolve_calibration_path(name_or_path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise CalibrationError(f"{path}: cannot read the calibration: {err}") from err
    check_document(doc, str(path))
    return doc, str(path)


def read_parameters(name_or_path: str) -> dict[str, float]:
    """A calibration file's parameters by name, as numbers.

    Raises:
        CalibrationError: as `read_document`, or a value that is not a number (named).
    """
    doc, source = read_document(name_or_path)
    out = {}
    for name, value in (doc.get("parameters") or {}).items():  # a mapping: read_document checked it
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CalibrationError(f"{source}: {name} must be a number, got {value!r}")
        out[str(name)] = float(value)
    return out
