"""Writes the step-gauge example tasks of Forbes 2025 section 7 (run from this folder).

26 steps of 10 mm at 20 mm pitch along x: left face of step k at x = 20(k-1) (normal -x),
right face at 20(k-1)+10 (normal +x).  Scenario I: one probe p = (0, 0, -20) mm.  Scenario II:
left faces with p_L = (0, 20, 0), right faces with p_R = (0, -20, 0).
"""
from pathlib import Path

from cmmwb.xlfuncs.model import TABLE3

HERE = Path(__file__).parent


def _num(v: float) -> str:
    """A Table 3 value as the task files write it: lengths of 100 mm and more without decimals."""
    return str(int(v)) if v >= 100 and v == int(v) else repr(float(v))


def _table3(mpe: str) -> dict:
    """Forbes 2025 Table 3, column ``mpe`` (:data:`xlfuncs.model.TABLE3`), as task-file text."""
    sc = TABLE3[mpe]
    p = sc.params
    out = {n: _num(getattr(p, n)) for n in ("sigma_R_um", "sigma_PQ_um", "sigma_ET_um", "lambda_ET_mm",
                                            "sigma_ER_urad", "lambda_ER_mm", "sigma_P0_um", "sigma_P_um")}
    out.update(A_um=_num(sc.A_um), B_mm=_num(sc.B_mm), s=_num(p.sigma_S_ppm), half_PQ=repr(p.sigma_PQ_um / 2))
    return out


def points(scenario):
    rows = ["# Step gauge of Forbes 2025 section 7, scenario " + scenario, "id,x,y,z,nx,ny,nz,probe"]
    for k in range(1, 27):
        x = 20 * (k - 1)
        rows.append(f"L{k},{x},0,0,-1,0,0,{'P1' if scenario == 'I' else 'PL'}")
        rows.append(f"R{k},{x + 10},0,0,1,0,0,{'P1' if scenario == 'I' else 'PR'}")
    return "\n".join(rows) + "\n"


def task(scenario, mpe):
    p = _table3(mpe)
    probes = ('[[probes]]\nid = "P1"\noffset_mm = [0.0, 0.0, -20.0]\nsigma_PQ_um = {h}\n' if scenario == "I" else
              '[[probes]]\nid = "PL"\noffset_mm = [0.0, 20.0, 0.0]\nsigma_PQ_um = {h}\n\n'
              '[[probes]]\nid = "PR"\noffset_mm = [0.0, -20.0, 0.0]\nsigma_PQ_um = {h}\n').format(h=p["half_PQ"])
    dist = []
    for k in range(2, 27):
        dist.append(f'  {{from = "L1", to = "L{k}", group = "LL"}},')
    for k in range(1, 27):
        dist.append(f'  {{from = "L1", to = "R{k}", group = "LR"}},')
    for k in range(2, 27):
        dist.append(f'  {{from = "R1", to = "R{k}", group = "RR"}},')
    for k in range(2, 27):
        dist.append(f'  {{from = "L{k}", to = "R{k}", group = "FF"}},')
    return f'''# Forbes 2025 section 7: step gauge, scenario {scenario}, statistical parameters {mpe} of Table 3.
# Reproduces Table {4 if scenario == "I" else 5} (rows L1-R1, L1-L2, L1-L26, L1-R26) and Figures 4-7.

# distances of Figures 6/7: first left face to every face, first right face to every right face,
# and each step's own length (FF)
distances = [
{chr(10).join(dist)}
]

[task]
kind = "pointcloud"
name = "stepgauge_{scenario}_{mpe}"
notes = [
  "The [decision] tolerances and measured values are realistic drawing tolerances and illustrative values chosen for cmmwb's demonstration, not taken from the paper.",
  "Forbes 2025 Table 5 prints u_PQ = sigma_PQ/sqrt(2) for two-probe distances; eq. (9)/(34) would give sigma_PQ*sqrt(2). The tables are reproduced with sigma_PQ,k = sigma_PQ/2 per probe (probe overrides); [parameters] sigma_PQ_um keeps Table 3's value for the summary formula (33)-(34).",
  "P_mm = 50 is Table 3's longest probe length for the MPE check; the step-gauge probes are 20 mm long.",
]

[mpe]
A_um = {p["A_um"]}
B_mm = {p["B_mm"]}
K = 2
P_mm = 50
L_max_mm = 1000

[parameters]
sigma_R_um = {p["sigma_R_um"]}
sigma_S_ppm = {p["s"]}
sigma_Sa_ppm = {p["s"]}
sigma_Q_ppm = {p["s"]}
sigma_PQ_um = {p["sigma_PQ_um"]}
sigma_ET_um = {p["sigma_ET_um"]}
lambda_ET_mm = {p["lambda_ET_mm"]}
sigma_ER_urad = {p["sigma_ER_urad"]}
lambda_ER_mm = {p["lambda_ER_mm"]}
sigma_P0_um = {p["sigma_P0_um"]}
sigma_P_um = {p["sigma_P_um"]}
lambda_P = 0.5

{probes}
[points]
file = "stepgauge_{scenario}.csv"

# Conformity decisions (not in the paper): realistic permissible deviations of the step gauge's
# lengths (± 1.5 µm up to 100 mm, ± 3 µm beyond) and illustrative measured values; the specific-risk
# rule of JCGM 106:2012, 9.3 accepts a length when its probability of conformance is >= 0.95.
[decision]
rule = "specific_risk"
max_pfa = 0.05

[[decision.tolerances]]    # first step, 20 mm
from = "L1"
to = "L2"
tol_mm = 0.0015
measured_mm = 20.0004

[[decision.tolerances]]    # one face to another, 500 mm
from = "L1"
to = "L26"
tol_mm = 0.003
measured_mm = 500.0021

[[decision.tolerances]]    # the whole gauge, 510 mm
from = "L1"
to = "R26"
tol_mm = 0.003
measured_mm = 509.9988
'''


if __name__ == "__main__":
    for s in ("I", "II"):
        (HERE / f"stepgauge_{s}.csv").write_text(points(s))
        for m in ("MPE1", "MPE2"):
            (HERE / f"stepgauge_{s}_{m}.toml").write_text(task(s, m))
