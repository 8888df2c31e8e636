"""Appearance jitter of the input events: dropout, polarity flips and local rate scaling.

The network should find moving objects by their motion, not by how densely this simulator's
textures fire. A jittered stream thins its events by a drawn share, flips a drawn share of their
polarities, and thins them further by a smooth field over the sensor (a coarse grid of factors,
bilinearly interpolated), so that event density and polarity balance vary within and between
streams. Targets are untouched: only what the network sees changes.

The draw is per stream and the per-event choices are seeded by (stream seed, reference), so a
resumed run rebuilds exactly the voxel grids that the stream played.
"""

from dataclasses import dataclass

import numpy as np

# Coarse grid of the rate field: a few blobs across the sensor, each a region of its own density.
RATE_GRID = (3, 4)


class JitterRangeError(ValueError):
    """Jitter ranges outside what thinning and flipping can mean."""


@dataclass(frozen=True)
class JitterRanges:
    max_dropout: float = 0.5
    max_polarity_flip: float = 0.1
    min_rate: float = 0.25

    def __post_init__(self):
        if not 0.0 <= self.max_dropout < 1.0:
            raise JitterRangeError(f"maximum dropout {self.max_dropout}: accepted 0 to below 1")
        if not 0.0 <= self.max_polarity_flip <= 0.5:
            raise JitterRangeError(f"maximum polarity flip {self.max_polarity_flip}: accepted 0 to 0.5")
        if not 0.0 < self.min_rate <= 1.0:
            raise JitterRangeError(f"minimum local rate {self.min_rate}: accepted above 0 up to 1")


@dataclass(frozen=True)
class EventJitter:
    dropout: float = 0.0
    polarity_flip: float = 0.0
    min_rate: float = 1.0
    seed: int = 0

    @staticmethod
    def draw(rng: np.random.Generator, ranges: JitterRanges) -> "EventJitter":
        return EventJitter(
            dropout=float(rng.uniform(0.0, ranges.max_dropout)),
            polarity_flip=float(rng.uniform(0.0, ranges.max_polarity_flip)),
            # Log-uniform: halving the local rate is as likely as any other halving.
            min_rate=float(np.exp(rng.uniform(np.log(ranges.min_rate), 0.0))),
            seed=int(rng.integers(2**31)),
        )

    @property
    def is_identity(self) -> bool:
        return self.dropout == 0.0 and self.polarity_flip == 0.0 and self.min_rate == 1.0

    def rate_field(self, width: int, height: int) -> np.ndarray:
        """[height, width] keep factors in [min_rate, 1], smooth, fixed for the stream."""
        rows, cols = RATE_GRID
        coarse = np.exp(np.random.default_rng([self.seed, 0]).uniform(np.log(self.min_rate), 0.0, (rows, cols)))
        # Cell centres of the coarse grid sit at the sensor's corners and evenly between them.
        ys = np.linspace(0.0, rows - 1, height)
        xs = np.linspace(0.0, cols - 1, width)
        y0 = np.minimum(ys.astype(int), rows - 2)
        x0 = np.minimum(xs.astype(int), cols - 2)
        fy, fx = (ys - y0)[:, None], (xs - x0)[None, :]
        top = coarse[y0][:, x0] * (1 - fx) + coarse[y0][:, x0 + 1] * fx
        bottom = coarse[y0 + 1][:, x0] * (1 - fx) + coarse[y0 + 1][:, x0 + 1] * fx
        return (top * (1 - fy) + bottom * fy).astype(np.float32)

    def events(
        self, t: np.ndarray, x: np.ndarray, y: np.ndarray, on: np.ndarray, width: int, height: int, reference: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The jittered events of the window ending at `reference`: a subset, some polarities flipped."""
        if self.is_identity:
            return t, x, y, on
        rng = np.random.default_rng([self.seed, 1, reference])
        keep_probability = (1.0 - self.dropout) * self.rate_field(width, height)[y, x]
        kept = rng.random(t.size) < keep_probability
        flipped = rng.random(t.size) < self.polarity_flip
        on = on.astype(bool) ^ flipped
        return t[kept], x[kept], y[kept], on[kept]
