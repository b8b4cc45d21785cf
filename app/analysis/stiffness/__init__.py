"""Stiffness analytics on 25 cm profiles and reference data (pure numpy/scipy).

Modules: :mod:`regression` (least squares with autocorrelation-aware intervals),
:mod:`subsidence` (u = a ln Z + b), :mod:`unsprung_mass` (force vs acceleration),
:mod:`maintenance` (actions per bin vs amplitude), :mod:`superstructure`
(amplitude per superstructure type, outlying segments), :mod:`speed_norm`
(speed exponent and normalised indicator), :mod:`alignment` (km shift between
runs, per-segment repeatability).
"""
