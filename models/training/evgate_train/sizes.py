"""Model sizes by width: the paper's L model has a first encoder stage of 64 channels."""

BASE_CHANNELS = {"XS": 8, "S": 16, "M": 32, "L": 64}
STAGES = 4


class UnknownSizeError(ValueError):
    """A model size name that is not one of XS, S, M, L."""


def base_channels(size: str) -> int:
    try:
        return BASE_CHANNELS[size]
    except KeyError:
        accepted = ", ".join(BASE_CHANNELS)
        raise UnknownSizeError(f"unknown model size {size!r}; accepted: {accepted}") from None


def stage_channels(base: int) -> list[int]:
    return [base * 2**stage for stage in range(STAGES)]
