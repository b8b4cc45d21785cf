"""How the simulated sleeper-passage amplitude depends on speed: the speed response.

The simulator writes ``a_s(x, v) = K_type(x) * f_side(x) * R_type(v)``
(:mod:`app.simulate.track`): ``K_type * f_side`` is the amplitude at the
reference speed ``v_ref``, and the speed response ``R_type(v)`` (1 at
``v_ref``) is one of

* :class:`ResonanceResponse` (default) — the amplitude of a wheel on a
  discretely supported rail (:mod:`app.analysis.stiffness.track_dynamics`) for
  a support stiffness per superstructure type,
  ``R_type(v) = A(k_type, v) / A(k_type, v_ref)``: a wheel–track resonance
  swept by ``f_s = v / d_s``, not a power law in speed;
* :class:`PowerLawResponse` — the separable model of earlier versions,
  ``R(v) = (v / v_ref) ** alpha`` for every type.

Local stiffness variation (``f_side``, soft and hard spots) stays a factor on
the amplitude in both, so a location's amplitude relative to its type's is the
same at every speed (the ground truth of the stiffness index).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal, Protocol

import numpy as np

from app.analysis.stiffness.track_dynamics import TrackParameters, sleeper_passage_amplitude
from app.analysis.units import KMH_PER_MPS
from app.simulate.track import SUPERSTRUCTURE_TYPES

__all__ = [
    "SpeedResponse",
    "PowerLawResponse",
    "ResonanceResponse",
    "DEFAULT_SUPPORT_STIFFNESS_MNM",
    "speed_response",
    "speed_response_from_json",
]

#: Support (ballast) stiffness per rail seat of each simulated superstructure type, MN/m.
DEFAULT_SUPPORT_STIFFNESS_MNM: dict[str, float] = {"slab": 320.0, "b91_no_pads": 110.0, "b91_pads": 40.0,
                                                   "timber": 60.0}
#: Speeds tabulated by :class:`ResonanceResponse`, m/s (log-spaced).
_TABLE_SPEEDS = np.geomspace(2.0, 150.0, 400)


class SpeedResponse(Protocol):
    """``R_type(v)``: amplitude at speed ``v`` relative to the amplitude at ``v_ref``."""

    kind: str
    v_ref_mps: float

    def factor(self, type_code: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        """``R`` per sample for superstructure type codes and speeds (m/s)."""
        ...

    def to_json(self) -> str:
        """The model's parameters (stored in the truth file)."""
        ...


def _check_speed(speed_mps: np.ndarray) -> np.ndarray:
    v = np.asarray(speed_mps, dtype=np.float64)
    if np.any(~(v > 0)):
        raise ValueError("speed_mps: must be > 0 m/s")
    return v


@dataclass(frozen=True)
class PowerLawResponse:
    """``R(v) = (v / v_ref) ** alpha`` for every superstructure type (the separable model)."""

    alpha: float = 1.5
    v_ref_mps: float = 100.0 / KMH_PER_MPS
    kind: Literal["power_law"] = "power_law"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.alpha) and self.alpha >= 0):
            raise ValueError(f"alpha must be a finite number >= 0, got {self.alpha!r}")
        if not (math.isfinite(self.v_ref_mps) and self.v_ref_mps > 0):
            raise ValueError(f"v_ref_mps must be a finite number > 0, got {self.v_ref_mps!r}")

    def factor(self, type_code: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        """``(v / v_ref) ** alpha`` (the type does not matter)."""
        v = _check_speed(speed_mps)
        return np.broadcast_to((v / self.v_ref_mps) ** self.alpha, np.broadcast_shapes(
            np.shape(type_code), v.shape)).copy()

    def to_json(self) -> str:
        return json.dumps({"kind": self.kind, "alpha": self.alpha, "v_ref_mps": self.v_ref_mps})


@lru_cache(maxsize=32)
def _log_table(params: TrackParameters) -> np.ndarray:
    """``ln A(k, v)`` on :data:`_TABLE_SPEEDS` (m/s²)."""
    return np.log(sleeper_passage_amplitude(params, _TABLE_SPEEDS))


@dataclass(frozen=True)
class ResonanceResponse:
    """``R_type(v) = A(k_type, v) / A(k_type, v_ref)`` of a wheel on a discretely supported rail.

    Attributes
    ----------
    support_stiffness_mnm : tuple of (str, float)
        Support stiffness per rail seat of each superstructure type, MN/m
        (default :data:`DEFAULT_SUPPORT_STIFFNESS_MNM`).
    damping_factor : float
        Pad and ballast damping relative to the physics reference runs'
        (28 and 47 kNs/m). Default 2: real track is more damped than that
        lightly damped model, so the resonance peaks are lower and wider.
    v_ref_mps : float
        Reference speed, m/s (``R = 1`` there).
    track : TrackParameters
        Rail, pad, sleeper, wheel and load (its ballast stiffness and damping
        are replaced per type).
    reference_track : TrackParameters, optional
        The vehicle ``K_type`` is the amplitude of at ``v_ref`` (default ``track``): another
        vehicle on the same line (e.g. a heavier unsprung mass) is
        ``R = A(track, k_type, v) / A(reference_track, k_type, v_ref)``, its own resonance
        against the line's amplitudes.

    ``A(k, v)`` is tabulated once per type on 2 … 150 m/s (400 log-spaced
    speeds) and interpolated linearly in ``(ln v, ln A)``.
    """

    support_stiffness_mnm: tuple[tuple[str, float], ...] = tuple(DEFAULT_SUPPORT_STIFFNESS_MNM.items())
    damping_factor: float = 2.0
    v_ref_mps: float = 100.0 / KMH_PER_MPS
    track: TrackParameters = TrackParameters()
    kind: Literal["resonance"] = "resonance"
    reference_track: TrackParameters | None = None

    def __post_init__(self) -> None:
        stiff = dict(self.support_stiffness_mnm)
        missing = set(SUPERSTRUCTURE_TYPES) - set(stiff)
        if missing:
            raise ValueError(f"support_stiffness_mnm: lacks types {sorted(missing)}")
        if not all(math.isfinite(k) and k > 0 for k in stiff.values()):
            raise ValueError("support_stiffness_mnm: stiffnesses must be finite and > 0 MN/m")
        if not (math.isfinite(self.damping_factor) and self.damping_factor >= 0):
            raise ValueError(f"damping_factor must be a finite number >= 0, got {self.damping_factor!r}")
        if not (_TABLE_SPEEDS[0] <= self.v_ref_mps <= _TABLE_SPEEDS[-1]):
            raise ValueError(f"v_ref_mps must be within {_TABLE_SPEEDS[0]:g} … {_TABLE_SPEEDS[-1]:g} m/s")

    def params(self, type_name: str, *, reference: bool = False) -> TrackParameters:
        """The track of one superstructure type (``reference``: under the reference vehicle)."""
        base = self.reference_track if reference and self.reference_track is not None else self.track
        return base.replace(
            ballast_stiffness=dict(self.support_stiffness_mnm)[type_name] * 1e6,
            ballast_damping=47e3 * self.damping_factor,
            pad_damping=28e3 * self.damping_factor,
        )

    def amplitude(self, type_name: str, speed_mps: np.ndarray, *, reference: bool = False) -> np.ndarray:
        """``A(k_type, v)``: the model's absolute amplitude, m/s² (``reference``: of the reference vehicle)."""
        v = _check_speed(speed_mps)
        if np.any(v < _TABLE_SPEEDS[0]) or np.any(v > _TABLE_SPEEDS[-1]):
            raise ValueError(f"speed_mps: must be within {_TABLE_SPEEDS[0]:g} … {_TABLE_SPEEDS[-1]:g} m/s")
        return np.exp(np.interp(np.log(v), np.log(_TABLE_SPEEDS),
                                _log_table(self.params(type_name, reference=reference))))

    def factor(self, type_code: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        """``A(k_type, v) / A_ref(k_type, v_ref)`` per sample (``A_ref``: the reference vehicle's)."""
        v = _check_speed(speed_mps)
        code = np.asarray(type_code)
        code, v = np.broadcast_arrays(code, v)
        out = np.empty(v.shape)
        for i, name in enumerate(SUPERSTRUCTURE_TYPES):
            m = code == i
            if m.any():
                ref = self.amplitude(name, np.array([self.v_ref_mps]), reference=True)[0]
                out[m] = self.amplitude(name, v[m]) / ref
        return out

    def to_json(self) -> str:
        doc = {"kind": self.kind, "support_stiffness_mnm": dict(self.support_stiffness_mnm),
               "damping_factor": self.damping_factor, "v_ref_mps": self.v_ref_mps,
               "track": {k: v for k, v in vars(self.track).items()}}
        if self.reference_track is not None:
            doc["reference_track"] = dict(vars(self.reference_track))
        return json.dumps(doc)


def speed_response(kind: str, *, v_ref_mps: float, alpha: float = 1.5) -> SpeedResponse:
    """The default model of a kind: ``"resonance"`` or ``"power_law"`` (with ``alpha``)."""
    if kind == "resonance":
        return ResonanceResponse(v_ref_mps=v_ref_mps)
    if kind == "power_law":
        return PowerLawResponse(alpha=alpha, v_ref_mps=v_ref_mps)
    raise ValueError(f"amplitude_model must be 'resonance' or 'power_law', got {kind!r}")


def speed_response_from_json(text: str) -> SpeedResponse:
    """Inverse of ``to_json`` (truth files)."""
    d: dict[str, Any] = json.loads(text)
    if d.get("kind") == "power_law":
        return PowerLawResponse(alpha=float(d["alpha"]), v_ref_mps=float(d["v_ref_mps"]))
    if d.get("kind") == "resonance":
        return ResonanceResponse(
            # a file written before a type was appended lacks it: the default (no sample of the file has it)
            support_stiffness_mnm=tuple((str(k), float(v)) for k, v in
                                        {**DEFAULT_SUPPORT_STIFFNESS_MNM, **d["support_stiffness_mnm"]}.items()),
            damping_factor=float(d["damping_factor"]), v_ref_mps=float(d["v_ref_mps"]),
            track=TrackParameters(**d["track"]),
            reference_track=TrackParameters(**d["reference_track"]) if d.get("reference_track") else None,
        )
    raise ValueError(f"unknown amplitude model {d.get('kind')!r}")
