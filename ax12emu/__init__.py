"""ax12emu: a virtual Dynamixel AX-12+ bus speaking Protocol 1.0 byte for byte."""

__version__ = "0.1.0"

__all__ = ["__version__"]
