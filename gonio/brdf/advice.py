"""Core errors that say what to change, in the words of whoever shows them.

A core error knows which settings would help (raise the elevation limit, pass ``replace``) but
not what the user calls them: the CLI has flags (``--max-elevation``), the API has fields
(``max_elevation_deg``). :class:`AdvisedError` keeps the advice as a template with one
``{knob}`` field per setting, knobs named as the core's parameters. ``str(exc)`` fills them
with the core's words; a caller with its own names renders :meth:`AdvisedError.advise`.
"""

from __future__ import annotations

from collections.abc import Mapping


class AdvisedError(ValueError):
    """A problem and what would help, the settings in the advice named by ``{knob}`` fields.

    Parameters
    ----------
    problem : str
        What is wrong, complete on its own.
    advice : str
        What would help, a ``str.format`` template whose fields are knob names; empty for none.
    words : mapping of str to str, optional
        The core's wording of a knob where it is not the knob's own name (e.g. ``replace`` ->
        ``replace=True``).
    """

    def __init__(self, problem: str, advice: str = "",
                 words: Mapping[str, str] | None = None) -> None:
        self.problem = problem
        self.advice = advice
        self.words: dict[str, str] = dict(words or {})
        super().__init__(self.advise({}))

    def advise(self, names: Mapping[str, str]) -> str:
        """The message with each knob named as in ``names`` (else the core's words)."""
        if not self.advice:
            return self.problem
        return f"{self.problem}; {self.advice.format_map(_Words(names, self.words))}"

    def __reduce__(self) -> tuple[type[AdvisedError], tuple[str, str, dict[str, str]]]:
        # Keep the template through pickling (a process pool): the default would rebuild the
        # error from its worded message alone.
        return (type(self), (self.problem, self.advice, self.words))


class _Words(dict[str, str]):
    """Knob -> wording: the caller's name, else the core's wording, else the knob itself."""

    def __init__(self, names: Mapping[str, str], words: Mapping[str, str]) -> None:
        super().__init__({**words, **names})

    def __missing__(self, knob: str) -> str:
        return knob
