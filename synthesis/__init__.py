"""imbench synthesis library: LFT toolkit, discretisation, complex-formed helpers, LPV synthesis.

Modules (thesis sections in brackets):

- `synthesis.lft`             LFTs, Redheffer star product, LFT plants and controllers (2.4, 5.2-5.3)
- `synthesis.discretize`      bilinear discretisation as a star product with D_bl (5.4.1)
- `synthesis.complex_formed`  complex n <-> real 2n forms, T_C, the projection (3.3.2, 5.5)

Nothing in this package imports `bench` or `mock_hw`.
"""
