"""The two MPE statements of Forbes 2025 Table 3 and the hyper-parameters derived from them,
typed once (tests, benchmarks, demonstrations and examples take them from here).

``TABLE3[name]`` holds the MPE statement E = A + L/B (``A_um``, ``B_mm``), the probe length
``P_mm`` of the rotation term of eq. (33) and the :class:`Parameters`; ``MPE1`` and ``MPE2``
are the parameters alone.  lambda_P = 0.5 is Table 3's value for both (section 6.6: "in
general, a value of 1/2 is appropriate")."""

from __future__ import annotations

from dataclasses import dataclass

from .parameters import Parameters


@dataclass(frozen=True)
class Scenario:
    """One column of Forbes 2025 Table 3."""

    name: str
    A_um: float
    B_mm: float
    P_mm: float
    params: Parameters


def _column(name: str, A_um: float, B_mm: float, sigma_R: float, s: float, sigma_PQ: float,
            sigma_ET: float, lambda_ET: float, sigma_ER: float, lambda_ER: float,
            sigma_P0: float, sigma_P: float) -> Scenario:
    return Scenario(name, A_um, B_mm, 50.0, Parameters(
        sigma_R_um=sigma_R, sigma_S_ppm=s, sigma_Sa_ppm=s, sigma_Q_ppm=s, sigma_PQ_um=sigma_PQ,
        sigma_ET_um=sigma_ET, lambda_ET_mm=lambda_ET, sigma_ER_urad=sigma_ER, lambda_ER_mm=lambda_ER,
        sigma_P0_um=sigma_P0, sigma_P_um=sigma_P, lambda_P=0.5))


#: Forbes 2025 Table 3, column by column (A µm, B mm, sigma_R µm, sigma_S = sigma_S,a = sigma_Q
#: ppm, sigma_PQ µm, sigma_ET µm, lambda_ET mm, sigma_ER µrad, lambda_ER mm, sigma_P0 µm, sigma_P µm)
TABLE3: dict[str, Scenario] = {
    "MPE1": _column("MPE1", 1.0, 500.0, 0.20, 0.7, 0.20, 0.2, 200.0, 4.0, 400.0, 0.10, 0.10),
    "MPE2": _column("MPE2", 3.0, 200.0, 0.60, 2.1, 0.60, 0.6, 100.0, 12.0, 200.0, 0.30, 0.30),
}

MPE1: Parameters = TABLE3["MPE1"].params
MPE2: Parameters = TABLE3["MPE2"].params
