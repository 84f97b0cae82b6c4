"""A large test circuit: a ladder of N resistor + log-compliance segments.

    python benchmarks/ladder.py N [OUT.yaml] [--constant]

Pa (pressure source, 80 mmHg with a sine term) drives node n0; segment i = 1..N is a resistor
R_i from n_{i-1} to n_i and a Payne06 log compliance C_i from n_i to ground; the last node drains
through R_out into a venous pressure source Pv.  Totals are independent of N: the segment
resistances add up to R_total and the compliances to about the compliance of one Payne06
arterial store (per segment k = k_total * N, Vn = Vn_total / N), so the slowest time constant
stays put while the ladder gets finer (and stiffer).  2 N + 3 elements, 2 N + 4 unknowns, N states.
"""
from __future__ import annotations

import sys

R_TOTAL = 4.0      # mmHg*s/mL, sum of the segment resistances
R_OUT = 1.0        # mmHg*s/mL, last node -> venous source
K_TOTAL = 0.5      # 1/mL  (one store of the whole ladder's volume)
P0 = -2.0          # mmHg
VN_TOTAL = 3.0     # mL
PA, PV = 80.0, 5.0  # mmHg


def ladder_yaml(N: int, amplitude: float = 10.0, frequency: float = 1.0) -> str:
    """Netlist text of an N-segment ladder (amplitude 0 for a constant source)."""
    k = K_TOTAL * N
    vn = VN_TOTAL / N
    r = R_TOTAL / N
    lines = [f"name: ladder-{N}",
             f"description: {N} resistor + log-compliance segments (benchmarks/ladder.py)",
             "elements:",
             f"  - {{id: Pa, type: pressure_source, nodes: [n0, ground], value: {PA} mmHg, "
             f"amplitude: {amplitude} mmHg, frequency: {frequency} Hz}}"]
    for i in range(1, N + 1):
        lines.append(f"  - {{id: R_{i}, type: resistor, nodes: [n{i - 1}, n{i}], R: {r!r} mmHg*s/mL}}")
        lines.append(f"  - {{id: C_{i}, type: log_compliance, nodes: [n{i}, ground], k: {k!r} 1/mL, "
                     f"P0: {P0} mmHg, Vn: {vn!r} mL}}")
    lines.append(f"  - {{id: R_out, type: resistor, nodes: [n{N}, nv], R: {R_OUT} mmHg*s/mL}}")
    lines.append(f"  - {{id: Pv, type: pressure_source, nodes: [nv, ground], value: {PV} mmHg}}")
    return "\n".join(lines) + "\n"


def write_ladder(path: str, N: int, **kw) -> str:
    with open(path, "w") as f:
        f.write(ladder_yaml(N, **kw))
    return path


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    N = int(args[0]) if args else 1500
    text = ladder_yaml(N, amplitude=0.0 if "--constant" in sys.argv else 10.0)
    if len(args) > 1:
        with open(args[1], "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)
