"""FaultConfig: fault options as text (serve flags, URL query) parsed into data, and bad text refused."""

from __future__ import annotations

import pytest

from ax12emu.faults.config import FaultConfig
from ax12emu.protocol.packets import StatusError


def test_options_parse_into_the_config():
    """Single options take their last value, repeatable ones collect every value, in order."""
    config = FaultConfig.from_options({
        "drop": ["0.1", "0.25"], "fault_ids": ["1,3"], "seed": ["7"],
        "vanish": ["2", "3:1.0:0.25"], "duplicate": ["1:9"], "alarm": ["1:overload+overheating"], "stall": ["4"],
    })
    assert config == FaultConfig(
        drop=0.25, fault_ids=(1, 3), seed=7, vanish=((2, None, None), (3, 1.0, 0.25)), duplicate=((1, 9),),
        alarm=((1, int(StatusError.OVERLOAD | StatusError.OVERHEATING)),), stall=(4,),
    )
    assert config.active and not FaultConfig().active


def test_fault_config_rejects_bad_values():
    """Fractions outside 0..1, unknown alarms and malformed pairs are ValueErrors naming the option."""
    for options, message in (({"drop": ["2"]}, "drop"), ({"alarm": ["1:hot"]}, "unknown alarm"),
                             ({"duplicate": ["1"]}, "SLOT:ID"), ({"vanish": ["1:2"]}, "ID:EVERY_S:FOR_S")):
        with pytest.raises(ValueError, match=message):
            FaultConfig.from_options(options)


@pytest.mark.parametrize("text", ["inf", "nan", "-0.1", "61", "1e308"])
def test_a_reply_delay_it_cannot_time_is_refused(text):
    """An infinite delay was taken and overflowed the wire's pacing at the first delayed reply (the server died)."""
    with pytest.raises(ValueError, match="delay_s: expected seconds 0..60"):
        FaultConfig.from_options({"delay": ["1"], "delay_s": [text]})


def test_fault_ids_take_id_lists_as_ids_does():
    assert FaultConfig.from_options({"drop": ["1"], "fault_ids": ["1-3,7"]}).fault_ids == (1, 2, 3, 7)
    with pytest.raises(ValueError, match="fault_ids: ID 300 is outside"):
        FaultConfig.from_options({"drop": ["1"], "fault_ids": ["300"]})


def test_fault_ids_that_would_do_nothing_are_refused():
    """No servo answers as ID 7 here, and without drop, corrupt or delay the IDs name nothing: both ran silently."""
    from ax12emu.bus.bus import Bus

    with pytest.raises(ValueError, match=r"no servo on this wire answers as ID 7 \(its IDs: 1, 2\)"):
        FaultConfig(drop=1.0, fault_ids=(7,)).install(Bus([1, 2]))
    with pytest.raises(ValueError, match="none of them is given"):
        FaultConfig(fault_ids=(1,))
    assert FaultConfig(drop=1.0, fault_ids=(9,), duplicate=((2, 9),)).install(Bus([1, 2])).reply_ids == {9}


@pytest.mark.parametrize(("fields", "says"), [
    ({"duplicate": (2, 1)}, "duplicate takes a tuple of 2-tuples"),
    ({"alarm": (1, "overload")}, "alarm takes a tuple of 2-tuples"),
    ({"vanish": (1, None, None)}, "vanish takes a tuple of 3-tuples"),
    ({"stall": 1}, "stall takes a tuple of IDs"),
])
def test_one_fault_given_bare_in_python_is_refused_naming_its_field(fields, says):
    """It was taken, then failed deep inside install with a TypeError naming nothing."""
    with pytest.raises(ValueError, match=says):
        FaultConfig(**fields)


@pytest.mark.parametrize(("options", "says"), [
    ({"delay_s": ["0.5"]}, "delay_s: how late the delay option's replies leave .* delay is not given"),
    ({"drop": ["0.5"], "delay_s": ["0.5"]}, "delay_s: .* delay is not given"),
    ({"vanish": ["1:inf:1"]}, r"vanish: expected finite seconds in ID:EVERY_S:FOR_S, got '1:inf:1'"),
    ({"vanish": ["1:nan:1"]}, "vanish: expected finite seconds"),
    ({"duplicate": ["1:1"]}, "duplicate: 1:1 gives servo 1 the ID it was launched as, which changes nothing"),
    ({"duplicate": ["2:1", "2:3"]}, "duplicate: ID 2 named more than once"),
    ({"vanish": ["1", "1:10:1"]}, "vanish: ID 1 named more than once"),
    ({"vanish": ["3", "1", "2:4:1", "3:10:1", "1"]}, "vanish: ID 1, 3 named more than once"),
])
def test_a_setting_that_would_do_nothing_or_not_what_it_says_is_refused(options, says):
    """Each was served without a word: a reply delay with nothing delayed, a period of inf (gone for FOR_S, then
    never), a servo "duplicated" as its own ID, and a second vanish or duplicate of one servo replacing the first."""
    with pytest.raises(ValueError, match=says):
        FaultConfig.from_options(options)


def test_the_settings_beside_the_refused_ones_are_taken():
    """What the refusals leave alone: delay_s with delay, the default delay_s without it, one vanish and one duplicate
    per servo, each on its own servo."""
    config = FaultConfig.from_options({"delay": ["0.5"], "delay_s": ["0.5"], "vanish": ["1", "2:10:1"],
                                       "duplicate": ["3:1", "4:1"]})
    assert config.delay_s == 0.5 and len(config.vanish) == 2 and len(config.duplicate) == 2
    assert FaultConfig(drop=0.5, delay_s=0.1).delay_s == 0.1


def test_an_infinite_vanish_period_is_refused_from_python_too():
    from ax12emu.bus.bus import Bus
    from ax12emu.faults.injection import Faults

    faults = Faults(Bus([1]))
    with pytest.raises(ValueError, match="vanish: every_s must be a finite period, got inf"):
        faults.vanish(1, every_s=float("inf"), for_s=1.0)
    with pytest.raises(ValueError, match="vanish: every_s must be a finite period"):
        FaultConfig(vanish=((1, float("inf"), 1.0),)).install(Bus([1]))
    faults.vanish(1, every_s=2.0, for_s=1.0)
    assert faults.active(1)
