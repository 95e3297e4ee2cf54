"""The refinement's uncertainty budget and self-calibration, for either car (internal to it).

- ``moves``: how a tolerance moves either vehicle (Rozyn's stage's budget moves them too);
- ``refine_budget``: what each value left assumed contributes to the refined estimate;
- ``calibrate``: the sensors and corner values calibrated by the data (the augmented
  posterior), with ``sensing`` (the sensors' gains, positions, delay) and ``corners`` (each
  axle's springs, dampers, tyres, unsprung masses, anti-roll bars) as their parameters;
- ``geometry``: the spectrum's derivatives in the wheelbase and tracks.

Nothing is re-exported: the modules import one another, and the model's own modules import
``sensing``, so a re-export here would be an import cycle.
"""
