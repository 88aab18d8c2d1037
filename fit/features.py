"""Coordinate stage: input ports -> normalised fitting variables.

For a cylindrical target (R, theta, Z) the servo polynomials are fitted over
the Cartesian features ``xn = (x - D) / 2**kx = R cos(theta) / 2**kx``,
``yn = R sin(theta) / 2**kx`` and ``zn = (Z - Zc) / 2**kz``, which need far fewer
terms than a direct series in (R, theta, Z). cos and sin are themselves integer
series in ``t = theta / 2**kt`` (even and odd, from the theta symmetry), shared
by all servos. Scale factors are powers of two, so normalising is wiring only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .horner import horner
from .plan import PlanBuilder
from .polyfit import fit_lawson, total_degree_terms, vander

__all__ = ["TrigSeries", "CylinderFeatures", "fit_trig", "pow2_scale"]


def pow2_scale(half_range: float) -> int:
    """Smallest k with 2**k >= half_range."""
    return max(0, math.ceil(math.log2(half_range))) if half_range > 0 else 0


@dataclass(frozen=True)
class TrigSeries:
    """cos(theta) ~ C(t**2), sin(theta) ~ t * S(t**2) with t = theta_deg / 2**kt."""
    kt: int
    cos_coeffs: tuple[float, ...]   # in powers of t**2
    sin_coeffs: tuple[float, ...]
    max_error: float                # max |series - exact| over the theta range (sampled)


def fit_trig(theta_min: float, theta_max: float, tol: float) -> TrigSeries:
    """Lowest-degree cos/sin series over [theta_min, theta_max] with error <= tol."""
    kt = pow2_scale(max(abs(theta_min), abs(theta_max)))
    th = np.linspace(theta_min, theta_max, 8001)
    t = th / 2.0 ** kt
    pts = t[:, None]
    out = []
    for kind, target, parity in (("cos", np.cos(np.radians(th)), "even"),
                                 ("sin", np.sin(np.radians(th)), "odd")):
        for deg in range(1, 40):
            terms = [e for e in total_degree_terms(deg, [parity]) if parity == "even" or e[0] % 2]
            c, err = fit_lawson(vander(pts, terms), target, 15)
            if err <= tol:
                break
        else:
            raise RuntimeError(f"no {kind} series reaches {tol:g}")
        out.append((tuple(float(x) for x in c), err))
    return TrigSeries(kt, out[0][0], out[1][0], max(out[0][1], out[1][1]))


@dataclass(frozen=True)
class CylinderFeatures:
    """Normalised Cartesian features of a cylindrical target, and their plan nodes."""
    trig: TrigSeries
    kx: int           # xn = R cos / 2**kx, yn = R sin / 2**kx
    z_center: float   # on the Z input grid
    kz: int

    names = ("xn", "yn", "zn")

    @classmethod
    def for_robot(cls, robot, trig_tol: float) -> "CylinderFeatures":
        r, th, z = robot.inputs
        zc_q = round((z.min + z.max) / 2 * 2 ** z.frac_bits) / 2 ** z.frac_bits
        return cls(fit_trig(th.min, th.max, trig_tol), pow2_scale(r.max),
                   zc_q, pow2_scale(max(z.max - zc_q, zc_q - z.min)))

    def exact(self, r, theta, z) -> np.ndarray:
        """Feature values (N, 3) with exact trigonometry (what the fit targets)."""
        th = np.radians(theta)
        s = 2.0 ** -self.kx
        return np.stack([r * np.cos(th) * s, r * np.sin(th) * s, (z - self.z_center) * 2.0 ** -self.kz], 1)

    def build(self, b: PlanBuilder, fv: int, fc: int) -> list[int]:
        """Add the coordinate stage to ``b``: features with ``fv`` fractional bits.

        ``fc`` is the fractional precision of t**2, cos and sin.
        """
        rn, thn, zn = (b.input_nodes[n] for n in ("r", "theta", "z"))
        t = b.reinterpret(thn, b.frac(thn) + self.trig.kt)
        u = b.mul(t, t, fc)
        cos = horner(b, {(k,): c for k, c in enumerate(self.trig.cos_coeffs)}, [u], fc)
        sin = b.mul(t, horner(b, {(k,): c for k, c in enumerate(self.trig.sin_coeffs)}, [u], fc), fc)
        # Interval arithmetic on a Horner chain overestimates |cos| and |sin| ~10x, which
        # the servo polynomials would raise to the 8th power. Clamping to the true range
        # (plus the series error, so the clamp never moves a value away from the ideal)
        # keeps every later width tight.
        lim = int(np.ceil((1.0 + 1.5 * self.trig.max_error) * 2 ** fc))
        cos, sin = (b.clamp(v, -lim, lim) for v in (cos, sin))
        feats = []
        for trig in (cos, sin):
            p = b.mul(rn, trig)
            feats.append(b.align(b.reinterpret(p, b.frac(p) + self.kx), fv))
        zq = b.add(zn, b.const(-self.z_center, b.frac(zn)))
        feats.append(b.align(b.reinterpret(zq, b.frac(zq) + self.kz), fv))
        return feats
