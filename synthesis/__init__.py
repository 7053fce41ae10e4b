"""imbench synthesis library: LFT toolkit, discretisation, complex-formed helpers, LPV synthesis.

Modules (thesis sections in brackets):

- `synthesis.lft`             LFTs, Redheffer star product, LFT plants and controllers (2.4, 5.2-5.3)
- `synthesis.discretize`      bilinear discretisation as a star product with D_bl (5.4.1)
- `synthesis.complex_formed`  complex n <-> real 2n forms, T_C, the projection (3.3.2, 5.5)
- `synthesis.lmi`             discrete LPV synthesis LMIs with full-block multipliers, γ bisection (Thm 5.15, 5.3.3, 5.4.4)
- `synthesis.construct`       controller construction: extensions, scheduling, QMI by App. B (5.27)-(5.36), (5.63)
- `synthesis.verify`          independent checks: frozen H∞, analysis LMI (5.52), time-varying gain
- `synthesis.robust`          robust LPV with uncertain scheduling Δ̂ = Δ + E: Thm 7.1, Cor. 7.5, the ε iteration of 7.2
- `synthesis.models`          motor / flux-observer LFT (5.77)-(5.80), JL observer, the LPV flux observer design (5.6),
                              the quasi-LPV stator current controller (6.2, `synthesis.models.current_controller`)
- `synthesis.artifacts`       controllers as versioned npz + JSON files

Nothing in this package imports `bench` or `mock_hw` (an import-linter contract in pyproject.toml, checked in CI):
what needs both, such as Figs. 5.5 and 5.6 on the sweep engine, lives in the bench (`bench.workflows.reproductions`).
"""
