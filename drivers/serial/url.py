"""The ``serial://`` URL: which device and how to read it (:class:`rtseg.drivers.serial.source
.SerialSource` does the reading).

URL::

    serial:///dev/ttyUSB0?baud=921600&format=rtseg&suit=default17&stale=0.25

Options (all optional):

=================  ==========================================================================
``baud``           line speed, default 921600 (use 115200 for typical text sketches)
``format``         ``rtseg`` (binary, :mod:`rtseg.drivers.serial.codec`), ``text``, or ``auto``
                   (the default: binary, switching to text if text lines arrive first; see
                   :mod:`rtseg.drivers.serial.source`)
``suit``           suit profile name in ``config/suits.toml`` (default ``default17``)
``suits``          another suits TOML file to read the profile from
``stale``          seconds without a valid value before a sensor is reported lost (0.25)
``rate``           nominal frame rate in Hz (default: the suit's ``frame_rate``)
``queue``          frames buffered for a slow consumer (default 256, ~2 s at 120 Hz)
``backoff``        longest wait between reconnect attempts to a device that stays, s (0.5)
``wait``           1: start even if the device is absent and keep trying (default 0: error)
``exclusive``      1 (default): lock the port (flock) so two readers cannot share it
``tpose``          1: each orientation is its segment's rotation from a T-pose in a Y-up world
                   facing +Z or -Z (the suit's firmware calibrates so; the simulated suit does):
                   behaviour names use a standard T-pose's posture (``rtseg.core.standard_rig``)
``calibration``    a suit calibration file (``rtseg calibrate``,
                   ``rtseg.core.suit_calibration``): every frame's sensor orientations become
                   their segments' rotations from the T-pose it was made on, facing +Z, and
                   the rig's rest geometry is the standard T-pose's (``rest_pose``; no facing
                   probe); for raw sensor orientations (any mounting, a Z-up or Y-up sensor
                   world, any heading)
=================  ==========================================================================

Every bad value is refused with one :class:`rtseg.drivers.base.SourceError` line before the
device is opened (``rtseg.drivers.options``).
"""

from __future__ import annotations

from rtseg.core.profiles import suit_profile
from rtseg.core.suit_calibration import CalibrationError, SuitCalibration
from rtseg.drivers.base import SourceError
from rtseg.drivers.options import check_options, flag_option, number_option
from rtseg.drivers.serial.source import DEFAULT_BAUD, MAX_BAUD, SerialSource

_OPTIONS = ("backoff", "baud", "calibration", "exclusive", "format", "queue", "rate", "stale",
            "suit", "suits", "tpose", "wait")
#: accepted range of each numeric option
_RANGES = {"baud": (50, MAX_BAUD), "stale": (1e-3, 3600.0), "rate": (1e-3, 1e5),
           "queue": (1, 1_000_000), "backoff": (0.05, 3600.0)}


def open_url(location: str, options: dict[str, str]) -> SerialSource:
    """``serial://`` handler for :func:`rtseg.drivers.open_source`; see the module docstring."""
    check_options("serial", options, _OPTIONS)
    if not location:
        raise SourceError("serial URL needs a device path, e.g. serial:///dev/ttyUSB0")

    def num(key: str, kind: type, default):
        return number_option("serial", options, key, default, kind, _RANGES)

    tpose = flag_option("serial", options, "tpose")
    fmt = options.get("format") or "auto"      # empty: the default, as for numbers
    if fmt not in ("rtseg", "text", "auto"):
        raise SourceError(f"serial:// option format={fmt!r}: expected rtseg, text or auto")
    try:
        suit = suit_profile(options.get("suit") or "default17", options.get("suits") or None)
    except (KeyError, ValueError) as exc:
        # str(KeyError) is the repr of its message (quoted); say the message itself
        raise SourceError(f"serial source: {exc.args[0] if exc.args else exc}") from None
    calibration = None
    if "calibration" in options:
        if not options["calibration"].strip():
            raise SourceError("serial:// calibration= needs a file (rtseg calibrate writes "
                              "one); leave the option out to read the sensors raw")
        try:
            calibration = SuitCalibration.load(options["calibration"])
            calibration.check_joints(suit.bones, f"suit {suit.name}")
        except CalibrationError as exc:
            raise SourceError(f"serial:// {exc}") from None
    src = SerialSource(
        location, baud=num("baud", int, DEFAULT_BAUD), fmt=fmt,
        suit=suit,
        stale=num("stale", float, 0.25), rate=num("rate", float, None),
        queue_size=num("queue", int, 256), backoff_max=num("backoff", float, 0.5),
        wait=flag_option("serial", options, "wait"),
        exclusive=flag_option("serial", options, "exclusive", True))
    src.calibration = calibration
    src.t_pose_without_geometry = tpose and calibration is None     # calibrated: rest_pose
    return src


__all__ = ["open_url"]
