"""The protocol layer stays pure: importing it brings in no model, no transport, no serving loop."""

from __future__ import annotations

import json
import subprocess
import sys


def _modules_after(statement: str) -> list[str]:
    code = f"import sys, json; {statement}; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    return json.loads(out.stdout)


def test_protocol_imports_no_model_and_no_transport():
    """`import ax12emu.protocol` loads neither firmware_model nor any transport, bus or serving code."""
    loaded = _modules_after("import ax12emu.protocol")
    assert "ax12emu.protocol.control_table" in loaded  # the check sees what it imported
    # (pyserial, which the URL handler registration imports, brings the standard library's select;
    # that the protocol code itself uses no I/O is import-linter's contract in pyproject.toml.)
    forbidden = [m for m in loaded if m.startswith(("firmware_model", "ax12emu.serve", "ax12emu.bus", "ax12emu.servo",
                                                    "ax12emu.harness.virtual_bus", "ax12emu.harness.inprocess"))]
    assert forbidden == []


def test_import_ax12emu_stays_light():
    """`import ax12emu` registers the URL handler and loads the bus and model only on first use."""
    loaded = _modules_after("import ax12emu")
    assert "ax12emu.harness.urlhandler" in loaded
    assert not [m for m in loaded if m.startswith(("firmware_model", "ax12emu.bus", "ax12emu.harness.virtual_bus"))]
