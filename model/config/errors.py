"""The error of a configuration that does not hold, naming its field, and the checks that raise it."""

from __future__ import annotations


class ConfigError(ValueError):
    """An invalid configuration value, or a serialised config that does not match the code.

    Attributes:
        field: The offending field's name within its section, when known.
    """

    def __init__(self, message: str, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


def check_choice(owner: str, name: str, value: object, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ConfigError(f"{owner}.{name} must be one of {choices}, got {value!r}", name)


def check_positive_ints(owner: str, name: str, values: tuple[int, ...], length: int) -> None:
    if len(values) != length or any(int(v) != v or v < 1 for v in values):
        raise ConfigError(
            f"{owner}.{name} must be {length} positive integers, got {values!r}", name
        )
