"""The half car's uncertainty budget after the likelihood fit (internal to the refinement).

- ``augment``: the values the data can inform (suspension, tyres, unsprung masses, sensor
  positions) calibrated by Newton steps of the augmented posterior;
- ``calibration``: the sensors' relative gain and delay, fitted with the window;
- ``sensitivity``: the first-order effect of the values left assumed;
- ``budget``: the published covariance assembled from them, split by contributor.

Nothing is re-exported: the refinement (:mod:`rozyn_estimator.method.likelihood.fit`) imports
the modules themselves.
"""
