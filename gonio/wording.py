"""Counts in messages: "1 stage angle", "8 stage angles".

Messages the lab reads (the console, the CLI, API errors) put a count before a noun; written as
``f"{n} stage angles"`` they said "1 stage angles" for a one-angle scan or a one-pair plan.
"""

from __future__ import annotations


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, the noun plural unless ``n`` is 1.

    Parameters
    ----------
    n
        The count.
    noun
        The noun in the singular; its last word takes the plural (``"stage angle"``).
    plural
        The plural when it is not ``noun`` + ``"s"``.

    Returns
    -------
    str
        ``"1 stage angle"``, ``"0 stage angles"``, ``"12 pairs"``.
    """
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


DAMAGED = " is an HDF5 file but damaged"
"""The words of :class:`gonio.results.ResultFileError` for an HDF5 file that cannot be read
whole (cut short in a copy or by a full disk), after the file's name: a caller that knows
the job adds how to write it again (the daemon names the job's rebuild command), the command
line what to do (:data:`DAMAGED_ADVICE`). Here, not in gonio.results, so that the command
line's error handler reads them without loading h5py and numpy."""

DAMAGED_ADVICE = (
    "if it is a copy, copy it again from the daemon's data directory (results/job-N.h5) or "
    "the page's 'Download HDF5 result'; if that one is damaged too, 'gonio jobs rebuild N "
    "--db DATA_DIR' writes it again from the job's stored readings")


SIM_CONFIG_HEADER = ("# Written by gonio sim for the simulated rig it runs; the next gonio sim "
                     "with this -o replaces it.\n")
"""The first line of a rig config the simulator writes (``gonio rig apply-design`` keeps it):
``gonio sim -o`` replaces such a file without asking, and refuses any other (a lab's own rig
config) unless told ``--overwrite``. Not the simulator's specimen recipe beside it: that file
outlives the config it was written for (a lab copying its own config over the name)."""
