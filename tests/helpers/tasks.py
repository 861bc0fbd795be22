"""Writers of point-cloud task files for tests (random clouds with several probes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

ALL_FACTORS = dict(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.8, sigma_Q_ppm=0.9, sigma_PQ_um=0.2,
                   sigma_ET_um=0.3, lambda_ET_mm=150, sigma_ER_urad=4.0, lambda_ER_mm=350,
                   sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.5)


def write_random_task(folder: Path, seed: int, m: int = 8, probes: int = 2, name: str | None = None,
                      labels: list[str] | None = None, mpe: bool = True) -> Path:
    rng = np.random.default_rng(seed)
    X = rng.uniform(-300, 300, (m, 3))
    N = rng.normal(size=(m, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    labels = labels or [f"Q{i + 1}" for i in range(m)]
    rows = ["id,x,y,z,nx,ny,nz,probe"]
    for i in range(m):
        rows.append(",".join([labels[i], *(f"{v:.17g}" for v in X[i]), *(f"{v:.17g}" for v in N[i]),
                              f"P{i % probes + 1}"]))
    name = name or f"random_{seed}"
    (folder / f"{name}.csv").write_text("\n".join(rows) + "\n")
    probe_txt = ""
    for k in range(probes):
        off = rng.uniform(-40, 40, 3)
        probe_txt += f'[[probes]]\nid = "P{k + 1}"\noffset_mm = [{off[0]:.17g}, {off[1]:.17g}, {off[2]:.17g}]\n'
        if k == 1:
            probe_txt += "sigma_PQ_um = 0.3\nsigma_P0_um = 0.05\n"
        probe_txt += "\n"
    params = "\n".join(f"{k} = {v}" for k, v in ALL_FACTORS.items())
    mpe_txt = '[mpe]\nA_um = 1.5\nB_mm = 400\nK = 2\n' if mpe else ""
    path = folder / f"{name}.toml"
    path.write_text(f'[task]\nkind = "pointcloud"\nname = "{name}"\n\n{mpe_txt}\n[parameters]\n{params}\n\n'
                    f'{probe_txt}[points]\nfile = "{name}.csv"\n')
    return path
