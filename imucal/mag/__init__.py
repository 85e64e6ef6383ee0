"""The magnetometer: the paper's model read as a hard- and soft-iron ellipsoid (issue 26).

  model.py      the map raw -> calibrated field and the residuals of its evidence, once in CasADi
  units.py      field units (gauss, uT, nT, mG) and the field magnitude a user gives
  evidence.py   the rows of a fit: |m| - F at every sample, the dip angle at still poses, the lag
  frame.py      the magnetometer's axes in the accelerometer's frame, found without a hint
  fit.py        initial guess, coverage check, the fit on the one least-squares path, the soft-iron test
  checks.py     what real logs do: a field that steps between poses, too few directions
  result.py     typed results: residuals in % of the field, dip scatter, before and after, per pose
  simulate.py   logs with known hard/soft iron and misalignment
"""
