"""The model-discrepancy workflow: measured trace in, named missing effects and better parameters out.

Why it is a subpackage apart: it does I/O (CSV traces, report files, plots,
TOML) and uses scipy; the model modules of :mod:`firmware_model` stay pure
numpy with no I/O, and nothing there imports this.

Modules, one job each: :mod:`.trace` (CSV format, reader and writer),
:mod:`.wizard` (DYNAMIXEL Wizard 2 graph exports), :mod:`.schedule` (commands
to whole-step segments), :mod:`.nuisance` (how the data was taken: hold
phase, command onsets, fitted with the base model and never named), :mod:`.replay` (the
trace through ``PhysicalModel``), :mod:`.batch` (many parameter sets at
once), :mod:`.phases` (motion phases), :mod:`.metrics` (scales, costs,
gaps), :mod:`.effects` (the effect library), :mod:`.evaluate` (batched
scoring, lockstep fits), :mod:`.search` (forward selection: the round
loop), :mod:`.selection` (screening and fitting candidates),
:mod:`.verdict` (the tests and rules that name, reject or mark tentative),
:mod:`.output` (verdict, report, parameter files), :mod:`.excitation` and
:mod:`.synthetic` (test data), :mod:`.cli`.  X-series servos (Protocol 2.0): :mod:`.xreplay`
(an X-series trace through the X firmware over its physics: their simulator), :mod:`.families`
(which simulator and effect library a trace's servo family takes), :mod:`.bam_trace` (BAM pendulum
logs as X-series traces), :mod:`.bam_fit` (the XL330 physics fitted to those logs).
"""

from .effects import LIBRARY, Effect, Param
from .replay import replay
from .search import Candidate, Diagnosis, diagnose
from .trace import Trace, TraceFormatError, read_trace, write_trace

__all__ = ["LIBRARY", "Effect", "Param", "replay", "Candidate", "Diagnosis", "diagnose", "Trace",
           "TraceFormatError", "read_trace", "write_trace"]
