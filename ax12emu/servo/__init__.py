"""One servo's firmware: its control table and options, request handling, and the plant adapter to a model.

Above :mod:`ax12emu.protocol`; the model behind the plant is a
:class:`firmware_model.interface.ServoModel`.
"""

from .model_factory import MODELS, ModelChoice, build_model, parse_arm
from .plant import Plant
from .request_handler import handle
from .virtual_servo import ServoOptions, VirtualServo

__all__ = ["MODELS", "ModelChoice", "Plant", "ServoOptions", "VirtualServo", "build_model", "handle", "parse_arm"]
