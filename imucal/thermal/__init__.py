"""Temperature calibration from still poses held over a temperature sweep (issue 27).

A sensor that does not move feels one gravity vector in its own frame: whatever its calibrated
reading does with temperature, within one pose, is the temperature terms' error. That is a second
kind of evidence besides |a| = g (imucal.solve.fit), and the one that tells bias(T) from scale(T):
an axis that reads about 0 g in a pose shows its bias(T) there, the axis that reads g shows
bias(T) + g scale(T). The pieces:

- ``evidence``: still intervals cut into rows at temperature steps (``ThermalRows``);
- ``fit``: the pose-constancy fit, a(raw, T; p) - v_pose, through the model's own CasADi map;
- ``determine``: what the poses determine, and what to record for what they do not;
- ``select``: the orders, chosen by the grammar's own forward test (imucal.analysis.discover);
- ``lag``: a lagging temperature sensor or hysteresis, named only when the data show it;
- ``run``: the whole thermal calibration (``imucal discover`` turns it into a Discovery).
"""
