"""The weights w of the iterations' two-step acceleration (Wang 2015, Eq. 12), x^{k+1} = x^{k−1} +
w_{k+1} (x̂^{k+1} − x^{k−1}). A mode that a plain iteration scales by λ, k iterations scale by P_k(λ):
P_0 = 1, P_1 = λ, P_{k+1} = w_{k+1} λ P_k + (1 − w_{k+1}) P_{k−1} (docs/METHOD.md, "Accelerated iterations").
"""

from __future__ import annotations

import math

import numpy as np

REVERSAL = 0.25
"""The most any error mode may be reversed (P_k ≥ −REVERSAL), inside the 1/3 past which substeps pump it."""
WEIGHT_CAP = 1.9
"""The largest stable weight: a mode keeps at least √(w − 1) of itself an iteration, so toward 2 none decays."""
SPECTRUM_SAMPLES = 4001
"""Points of the spectrum the polynomials are checked on."""


def stable_weights(lowest: float, count: int, reversal: float = REVERSAL) -> tuple[float, ...]:
    """w_1 … w_count for factors λ in [``lowest``, 1]: each the largest w ≤ WEIGHT_CAP keeping
    −reversal ≤ P_k ≤ 1 (P_{k+1} = a + w b is linear in w, so the bound is a minimum over λ)."""
    lam = np.linspace(lowest, 1.0, SPECTRUM_SAMPLES)[:-1]  # at λ = 1 every P_k is 1, whatever w
    before, now = np.ones_like(lam), lam.copy()
    weights = [1.0]
    for _ in range(count - 1):
        a, b = before, lam * now - before
        rising, falling = b > 1e-12, b < -1e-12
        ceiling = min(
            np.min((1.0 - a[rising]) / b[rising], initial=math.inf),
            np.min((a[falling] + reversal) / -b[falling], initial=math.inf),
            WEIGHT_CAP,
        )
        floor = max(
            np.max((-reversal - a[rising]) / b[rising], initial=-math.inf),
            np.max((a[falling] - 1.0) / -b[falling], initial=-math.inf),
            1.0,
        )
        if not ceiling >= floor:
            raise ValueError(
                f"no weight keeps iteration {len(weights) + 1} within [−{reversal}, 1] on the spectrum "
                f"[{lowest:.3g}, 1]"
            )
        weight = float(ceiling)
        weights.append(weight)
        before, now = now, weight * lam * now + (1.0 - weight) * before
    return tuple(weights)


def chebyshev_weights(rho: float, count: int) -> tuple[float, ...]:
    """w_1 … w_count of Chebyshev semi-iterative acceleration (Wang 2015, Eq. 12) for spectral radius ρ:
    1, 2 / (2 − ρ²), then 4 / (4 − ρ² w_prev), falling toward 2 / (1 + √(1 − ρ²)); all 1 at ρ = 0."""
    weights = [1.0]
    rho2 = rho * rho
    for _ in range(count - 1):
        last = weights[-1]
        weights.append(1.0 if rho2 == 0.0 else 2.0 / (2.0 - rho2) if last == 1.0 else 4.0 / (4.0 - rho2 * last))
    return tuple(weights)
