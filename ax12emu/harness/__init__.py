"""The ways into a bus from test code: VirtualBus, the in-process link, the ``ax12emu://`` URL handler, the pytest plugin.

Kept import-light on purpose: ``import ax12emu`` registers the URL handler
from here, so nothing heavier is imported until it is used.
"""

__all__: list[str] = []
