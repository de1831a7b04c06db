"""Running resistance (Davis formula), with unit conversion at the edge."""

from __future__ import annotations

from dataclasses import dataclass

from cosim.fmu.declare import Checked, param

KMH = 1.0 / 3.6  # m/s per km/h


@dataclass(frozen=True)
class Davis(Checked):
    """Basic running resistance ``F = a + b v + c v^2`` in N with v in m/s."""

    a: float = param(unit="N", description="Davis constant term a", min=0.0)
    b: float = param(unit="N.s/m", description="Davis linear term b", min=0.0)
    c: float = param(unit="N.s2/m2", description="Davis quadratic term c", min=0.0)

    @classmethod
    def from_kn_kmh(cls, a_kn: float, b_kn_per_kmh: float, c_kn_per_kmh2: float) -> Davis:
        """From coefficients in kN with v in km/h (seed 000 Table 1 reading, see SPEC)."""
        return cls(a_kn * 1e3, b_kn_per_kmh * 1e3 / KMH, c_kn_per_kmh2 * 1e3 / KMH**2)

    @classmethod
    def from_n_per_kn_kmh(cls, a: float, b: float, c: float, weight_kn: float) -> Davis:
        """From specific resistance in N/kN with v in km/h, for a vehicle of ``weight_kn``."""
        return cls.from_kn_kmh(a * weight_kn / 1e3, b * weight_kn / 1e3, c * weight_kn / 1e3)

    def force(self, v: float) -> float:
        """Resistance force (N) at speed ``v`` (m/s), v >= 0."""
        return self.a + (self.b + self.c * v) * v
