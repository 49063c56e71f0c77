"""The ``ax12emu`` command line: ``serve`` (:mod:`.main`), and trace, fault and conformance commands (:mod:`.hil`)."""

from .main import main, parse_args

__all__ = ["main", "parse_args"]
