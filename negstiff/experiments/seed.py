"""The reference study's own numbers (Anastasio, Fasana, Garibaldi, Marchesiello, EURODYN 2020), in one
place, so every report sets ours beside theirs.
"""

TABLE1 = {"minus": {"f_hz": 11.41, "zeta": 0.112}, "plus": {"f_hz": 9.19, "zeta": 0.203}}
"""Table 1: modal parameters of the two underlying-linear systems identified with NSI."""
Z_PLUS = 0.023
"""Section 3: the positive equilibrium position [m]."""
EQ8 = {"k3": 7.35e5, "k2_tilde": -6.45e3, "k1_tilde": 1.34e3}
"""Eq. (8): shifted restoring-force coefficients [N/m^3, N/m^2, N/m] (reference well not stated)."""
C_NL = -5.0
"""Section 4: identified quadratic damping coefficient [N s^2/m^2]."""
TABLE2 = {"residual_mean_mm": 0.18, "residual_std_mm": 1.0, "rms_percent": 8.0}
"""Table 2 and text: validation residual over the last 60 s of 300 s."""
GA_FITNESS_PERCENT = 1.38
"""Section 4.1: final GA fitness (Eq. 9)."""
CASCADE_M_S2 = (12.0, 15.0)
"""Section 3: period doublings near 12-15 m/s^2 at 9 Hz, starting from the positive well."""
