"""Small netlists with closed forms shared by several test files."""

# series R-L-C from a pressure source: resonance at 1/(2 pi sqrt(L C)), peak |Q/P| = 1/R
RLC_NET = """
name: rlc
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg}
  - {id: R1, type: resistor,        nodes: [in, a],      R: 2 mmHg*s/mL}
  - {id: L1, type: inductor,        nodes: [a, b],       L: 0.3 mmHg*s**2/mL}
  - {id: C1, type: compliance,      nodes: [b, ground],  C: 0.75 mL/mmHg, V0: 3 mL}
"""
R, L, C = 2.0, 0.3, 0.75  # mmHg*s/mL, mmHg*s^2/mL, mL/mmHg
