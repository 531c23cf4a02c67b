"""Rope-groove friction (EN 81-50 equivalent friction, Euler-Eytelwein limit) used by the traction
model (model.py) and by the trip analysis (analysis.py)."""
from __future__ import annotations

import math


def equivalent_friction(mu: float, beta_deg: float, gamma_deg: float, groove: str = "u-undercut") -> float:
    """Equivalent friction coefficient f of a groove (EN 81-50, docs/reference-sets.md §4.2).

    groove: "u-undercut" / "semicircular" (same formula, beta = undercut angle, 0 for none),
    "v-hardened" (f = mu / sin(gamma/2)), "v" (not hardened, uses beta)."""
    if not (mu > 0 and math.isfinite(mu)):
        raise ValueError(f"mu must be a positive number, got {mu!r}")
    b, g = math.radians(beta_deg), math.radians(gamma_deg)
    if groove in ("u-undercut", "semicircular"):
        if not (0.0 <= b < math.pi):
            raise ValueError(f"beta_deg must be in [0, 180), got {beta_deg!r}")
        if not (0.0 <= g < math.pi):
            raise ValueError(f"gamma_deg must be in [0, 180), got {gamma_deg!r}")
        den = math.pi - b - g - math.sin(b) + math.sin(g)
        num = 4.0 * (math.cos(g / 2.0) - math.sin(b / 2.0))
        if den <= 0.0 or num <= 0.0:
            raise ValueError(f"beta_deg={beta_deg!r}, gamma_deg={gamma_deg!r} give no valid groove geometry")
        return mu * num / den
    if groove == "v-hardened":
        if not (0.0 < g < math.pi):
            raise ValueError(f"gamma_deg must be in (0, 180), got {gamma_deg!r}")
        return mu / math.sin(g / 2.0)
    if groove == "v":
        if not (0.0 <= b < math.pi):
            raise ValueError(f"beta_deg must be in [0, 180), got {beta_deg!r}")
        return mu * 4.0 * (1.0 - math.sin(b / 2.0)) / (math.pi - b - math.sin(b))
    raise ValueError(f"groove must be 'u-undercut', 'semicircular', 'v-hardened' or 'v', got {groove!r}")


def traction_limit(mu: float, beta_deg: float, gamma_deg: float, alpha_deg: float,
                   groove: str = "u-undercut") -> float:
    """Capstan limit e^(f*alpha) for the groove (see `equivalent_friction`), wrap angle alpha in degrees."""
    if not (alpha_deg > 0 and math.isfinite(alpha_deg)):
        raise ValueError(f"alpha_deg must be a positive wrap angle, got {alpha_deg!r}")
    return math.exp(equivalent_friction(mu, beta_deg, gamma_deg, groove) * math.radians(alpha_deg))
