"""The one error a site file is refused with."""

from __future__ import annotations


class SiteError(ValueError):
    """A site file is unreadable or describes an impossible world.

    The message always starts with the file name, then the offending entry
    (``office.toml: doors[1] (id "d_x"): center ...``), so a refusal says where to look.
    ``file``, ``entry`` and ``problem`` keep the parts for programs.
    """

    def __init__(self, file: str, entry: str, problem: str) -> None:
        self.file = file
        self.entry = entry
        self.problem = problem
        where = f"{file}: {entry}: " if entry else f"{file}: "
        super().__init__(f"{where}{problem}")
