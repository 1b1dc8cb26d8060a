"""pytest fixtures that fly pymavlink scripts against the two-rotor VTOL twin (`firmware-sim
serve`): `vtol_twin`, one vehicle; `vtol_fleet(n)`, several. See the repository's README,
"Test your script against the twin"."""

from .twin import TrueState, TwinError, TwinOptions, VtolTwin, find_binary, start_fleet

__all__ = ["TrueState", "TwinError", "TwinOptions", "VtolTwin", "find_binary", "start_fleet"]
