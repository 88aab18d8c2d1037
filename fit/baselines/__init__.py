"""Baselines the ikseries fit is measured against, each with its own plan or datapath.

- :mod:`.paper`: the integer power series paper's own procedure (θ series per circle, R and Z
  fits, 7 significant figures), lowered to an evaluation plan.
- :mod:`.comparison`: the paper's plan beside ikseries' plan on the same points.
- :mod:`.divided`: divided-difference path mode of the planar arm (tool paths instead of a box).
- :mod:`.cordic`: the CORDIC leg solver's datapath, range analysis and formats (the RTL is
  :mod:`ikseries.hdl.cordic`, the golden model :mod:`ikseries.sim.cordic_golden`);
  :mod:`.cordic_sizing` sizes its iterations and widths to the tolerance.
"""
