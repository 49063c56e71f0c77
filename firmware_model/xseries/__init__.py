"""Firmware and physics of ROBOTIS X-series servos (Protocol 2.0): one model per servo, behind :mod:`.interface`."""
