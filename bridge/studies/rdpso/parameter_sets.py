"""The thesis' RDPSO parameter sets, shared by the study's experiments: Table 7.1's static sets S1 and S2 (digest
4.1), and the set of chapters 4-6 (Tables 4.3, 4.6, 5.1)."""

from __future__ import annotations

SETS: dict[str, dict[str, float]] = {
    "S1": {"alpha": 0.632, "rho1": 0.1, "rho2": 0.3, "rho3": 0.79, "rho4": 0.79},
    "S2": {"alpha": 0.632, "rho1": 0.4, "rho2": 0.69, "rho3": 0.2, "rho4": 0.69},
    "ch4": {"alpha": 0.5, "rho1": 0.2, "rho2": 0.4, "rho3": 0.8, "rho4": 0.8},
}
