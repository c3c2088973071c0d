"""``arroch study``: user studies with real participants (plan, run, report, calibrate)."""
