"""Settings of the likelihood refinement (the ``pipeline.likelihood.*`` parameters)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from rozyn_estimator.parameters import check, param


@dataclass(frozen=True)
class LikelihoodConfig:
    """Settings of the likelihood refinement. Frequencies in Hz."""

    PARAM_PREFIX: ClassVar[str] = "pipeline.likelihood."

    band_hz: tuple[float, float] = param((0.5, 15.0), "[min, max] frequency band of the fit", unit="Hz",
                                         low=0.0, open_low=True, length=2)
    max_band_nyquist: float = param(0.6, "the band ends at most at this share of the Nyquist frequency",
                                    low=0.0, open_low=True, high=1.0)
    taper: float = param(0.2, "share of the window under a cosine taper",
                         low=0.0, high=1.0)
    ramp_s: float = param(3.0, "a varying drive's steady stretches rise and fall over a raised cosine of "
                          "this length (a square cut spreads the body modes' power across the band)",
                          unit="s", low=0.0)
    aliases: int = param(1, "aliasing terms of the sampled spectrum modelled on each side", low=0, high=5)
    road_max_cpm: float = param(5.0, "the road's profile ends here (a tyre smooths shorter waves away): the "
                                "aliases hold the road below it only (0: no end)", unit="cycles/m", low=0.0)
    road_shape_terms: int = param(4, "smooth departures of the road spectrum from a power law", low=0, high=8)
    second_start: bool = param(True, "guard against wrong basins: a second start, the lower likelihood wins")
    self_calibrate: bool = param(True, "fit what the data can pin down as nuisances with their tolerances as "
                                 "priors: each sensor's gain and position, the rear sensors' delay, each "
                                 "corner's spring, damper, tyre and unsprung mass")
    max_noise_share: float = param(0.5, "a channel fitted as more noise than this share of its power fails",
                                   low=0.0, open_low=True, high=1.0)
    grid_hz: float = param(0.05, "the model is evaluated this far apart and interpolated between (0: at "
                           "every Fourier bin)", unit="Hz", low=0.0, high=0.1)
    max_iter: int = param(100, "optimiser iterations per start", low=1)
    tol: float = param(1e-3, "convergence: Newton decrement below this (ℓ within half of it of the optimum), "
                       "or the body parameters' part of it (their remaining step in their std, squared) "
                       "with ℓ within 0.05 nats", low=0.0, open_low=True)
    tol_calibrated: float = param(0.05, "convergence when the calibration's Newton step follows (it "
                                  "completes the fit's: measured, the estimates move by < 0.003 std; "
                                  "a cold fit hands over earlier, within the calibration's one-step "
                                  "range, and its result is held to this)",
                                  low=0.0, open_low=True)
    noise_start: float = param(1e-3, "the starts' noise floors, share of each channel's band power",
                               low=0.0, open_low=True, high=1.0)

    def __post_init__(self) -> None:
        check(self, (
            ("band_hz", lambda c: c.band_hz[0] < c.band_hz[1], "needs 0 < min < max"),
            ("noise_start", lambda c: c.noise_start < 1.0, "must lie in (0, 1)"),
        ))

    def band_at(self, fs_hz: float) -> tuple[float, float]:
        """The fit's band [Hz] at the sample rate ``fs_hz``: ``band_hz``, its top at most
        ``max_band_nyquist`` of the Nyquist frequency."""
        return self.band_hz[0], min(self.band_hz[1], self.max_band_nyquist * fs_hz / 2.0)
