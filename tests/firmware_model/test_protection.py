"""Heating and alarms, through the physical model."""

import numpy as np
import pytest

from firmware_model.interface import ALARM_INPUT_VOLTAGE, ALARM_OVERHEATING, ALARM_OVERLOAD
from firmware_model.physical import PhysicalModel


def test_stall_heats_to_the_overheating_alarm_and_cools(commands):
    """Stalled at full drive (9.6 V: 1.5 A, 14.6 W) the temperature passes 70 C within 30-90 s; torque off, it cools."""
    model = PhysicalModel(1)
    model.set_external_torque(-1.55)  # just below holding torque: the shaft stands still, full drive
    cmds = commands(goal_position=1000)
    times = []
    for second in range(1, 91):
        sensed = model.advance(float(second), cmds)
        assert model.speed_rad_s[0] == 0.0 or second < 2
        if sensed.alarms[0] & ALARM_OVERHEATING:
            times.append(second)
    assert 30 <= times[0] <= 90
    assert sensed.present_temperature[0] > 70
    hot = model.temperature_c[0]
    model.set_external_torque(0.0)
    sensed = model.advance(model.time_s + 300.0, commands(torque_enable=0))
    assert model.temperature_c[0] < hot - 20 and not sensed.alarms[0] & ALARM_OVERHEATING


def test_overload_needs_a_stalled_demand_above_the_limit(commands):
    """Torque Limit 30 % against an obstacle: overload after 0.5 s; a free move at full demand never raises it."""
    model = PhysicalModel(1)
    model.set_external_torque(-0.5)  # 30 % drive (0.42 N m) plus static friction hold it: a stall
    cmds = commands(goal_position=900, torque_limit=300)
    assert not model.advance(0.4, cmds).alarms[0] & ALARM_OVERLOAD
    assert model.advance(1.0, cmds).alarms[0] & ALARM_OVERLOAD
    free = PhysicalModel(1)
    for i in range(1, 101):
        assert not free.advance(i * 0.01, commands(goal_position=1000 if i < 50 else 20)).alarms[0] & ALARM_OVERLOAD


@pytest.mark.parametrize(("volts", "low", "high", "alarm"), [(9.6, 60, 140, False), (9.6, 100, 140, True), (12.0, 60, 110, True)])
def test_input_voltage_alarm(volts, low, high, alarm, commands):
    """Input-voltage bit while the supply is outside [Min, Max Voltage Limit] (0.1 V units)."""
    model = PhysicalModel(2)
    model.set_supply_voltage(volts)
    sensed = model.advance(0.01, commands(2, min_voltage_limit=low, max_voltage_limit=high))
    assert bool(sensed.alarms[0] & ALARM_INPUT_VOLTAGE) == alarm
    assert np.all(sensed.present_voltage == round(volts * 10))


@pytest.mark.parametrize("backend", ["scalar", "numpy"])
@pytest.mark.parametrize("pieces", [1, 600], ids=["60 s at once", "0.1 s pieces"])
def test_alarm_shutdown_cuts_the_drive_at_the_thermal_event_the_alarm_is_found(backend, pieces, commands):
    """Alarm Shutdown (a command) acts inside ``advance``: a blocked servo stepped 60 s at once heated at full
    drive for the whole minute (to 83 C) where 0.1 s pieces, each written back, ended at 30 C.  Now the drive
    limit drops to 0 at the thermal event Overload is found, however long the step, and the cut is reported
    (``output_cut``) until its Torque Limit, Torque Enable or Alarm Shutdown changes."""
    model = PhysicalModel(1, backend=backend)
    model.set_blocked(True)
    cmds = commands(goal_position=800, shutdown=ALARM_OVERLOAD)
    for k in range(1, pieces + 1):
        sensed = model.advance(60.0 * k / pieces, cmds)
    assert model.drive[0] == 0.0 and model.temperature_c[0] < 31.0
    assert sensed.alarms[0] & ALARM_OVERLOAD and sensed.output_cut.tolist() == [1]
    early = PhysicalModel(1, backend=backend)
    early.set_blocked(True)
    assert early.advance(0.45, cmds).output_cut.tolist() == [0] and early.drive[0] == 1.0  # before the delay
    assert early.advance(0.6, cmds).output_cut.tolist() == [1] and early.drive[0] == 0.0


def test_the_cut_holds_until_the_commands_change_and_a_new_torque_limit_is_judged_afresh(commands):
    """The bus writes the cut's 0 into Torque Limit; a Torque Limit written after it drives again for the overload
    delay (the timer restarts with a raised limit) before the still-blocked shaft cuts it once more."""
    model = PhysicalModel(1)
    model.set_blocked(True)
    model.advance(1.0, commands(goal_position=800, shutdown=ALARM_OVERLOAD))
    assert model.advance(2.0, commands(goal_position=800, shutdown=ALARM_OVERLOAD)).output_cut.tolist() == [1]
    shown = model.advance(2.0, commands(goal_position=800, shutdown=ALARM_OVERLOAD, torque_limit=0))
    assert shown.output_cut.tolist() == [0] and shown.alarms[0] & ALARM_OVERLOAD  # Torque Limit 0: no drive at all
    again = commands(goal_position=800, shutdown=ALARM_OVERLOAD)
    assert not model.advance(2.4, again).alarms[0] & ALARM_OVERLOAD and model.drive[0] == 1.0
    assert model.advance(2.6, again).output_cut.tolist() == [1] and model.drive[0] == 0.0


@pytest.mark.parametrize("backend", ["scalar", "numpy"])
def test_a_cut_holds_until_its_own_servos_torque_registers_change(backend, commands):
    """A cut ended at any change to the commands: a goal written (to that servo or another) before the bus wrote
    the cut's 0 dropped it, and Torque Limit, judged 'raised' from the cut's 0 to the register's unchanged 1023,
    restarted the overload timer, so the blocked servo drove at full power for another overload delay."""
    n = 1 if backend == "scalar" else 2
    model = PhysicalModel(n, backend=backend)
    model.set_blocked([True] + [False] * (n - 1))
    cmds = commands(n, goal_position=800, shutdown=ALARM_OVERLOAD)
    assert model.advance(0.6, cmds).output_cut.tolist() == [1] + [0] * (n - 1)
    goals = [[801] + [800] * (n - 1)] + ([[800, 300]] if n == 2 else [])
    for k, goal in enumerate(goals):  # its own goal, then another servo's: the cut holds, the timer runs on
        sensed = model.advance(0.6 + 0.3 * k, commands(n, goal_position=goal, shutdown=ALARM_OVERLOAD))
        assert sensed.output_cut[0] == 1 and sensed.alarms[0] & ALARM_OVERLOAD and model.drive[0] == 0.0
    # a lower Torque Limit written is no raise: the cut ends (the register says what the output is) and the alarm,
    # still there, cuts again at the next thermal event
    sensed = model.advance(1.3, commands(n, goal_position=goals[-1], shutdown=ALARM_OVERLOAD, torque_limit=800))
    assert sensed.output_cut[0] == 1 and sensed.alarms[0] & ALARM_OVERLOAD and model.drive[0] == 0.0
    for change in (dict(torque_limit=0), dict(torque_enable=0), dict(shutdown=0)):  # each of its own ends the cut
        fresh = PhysicalModel(n, backend=backend)
        fresh.set_blocked([True] + [False] * (n - 1))
        fresh.advance(0.6, cmds)
        assert fresh.advance(0.6, commands(n, goal_position=800, **{"shutdown": ALARM_OVERLOAD, **change})
                             ).output_cut.tolist() == [0] * n, change


@pytest.mark.parametrize("clears", ["torque_limit", "torque_enable"])
def test_alarm_bits_after_a_cut_do_not_depend_on_how_the_model_was_stepped(clears, commands):
    """The 2006 edition's cut is torque off.  Stepped 120 s at once, the cut (Torque Limit 0, torque on) counted as
    an overload against a limit of 0, and the servo read Overload where 1 s pieces, the bus writing Torque Enable 0
    at the first cut, did not.  A model told its edition's cut (``shutdown_clears``) reports the alarms the
    written register gives; the e-manual's Torque Limit 0 overloads (no drive is allowed) both ways."""
    def run(pieces):
        model = PhysicalModel(1, shutdown_clears=clears)
        model.set_blocked(True)
        cmds = commands(goal_position=900, shutdown=ALARM_OVERHEATING)
        for k in range(1, pieces + 1):
            sensed = model.advance(120.0 * k / pieces, cmds)
            if sensed.output_cut[0]:  # what the bus writes when shown the cut
                cmds = commands(goal_position=900, shutdown=ALARM_OVERHEATING, **{clears: 0})
        return int(sensed.alarms[0]), sensed.output_cut.tolist()

    at_once, in_pieces = run(1), run(120)
    assert at_once[1] == [1]
    assert at_once[0] == in_pieces[0] == (ALARM_OVERLOAD if clears == "torque_limit" else 0)
    with pytest.raises(ValueError, match="shutdown_clears"):
        PhysicalModel(1, shutdown_clears="torque")


def test_alarm_shutdown_0_leaves_the_drive_on(commands):
    """With no bit selected (power_up's default) the model only raises the alarms, as before."""
    model = PhysicalModel(1)
    model.set_blocked(True)
    sensed = model.advance(2.0, commands(goal_position=800))
    assert sensed.alarms[0] & ALARM_OVERLOAD and sensed.output_cut.tolist() == [0] and model.drive[0] == 1.0


@pytest.mark.parametrize("backend", ["scalar", "numpy"])
@pytest.mark.parametrize(("moving_speed", "torque_limit", "overload"), [(1023, 1023, True), (2047, 1023, True),
                                                                       (1023, 1022, True), (600, 1023, False)])
def test_a_blocked_wheel_overloads_when_its_output_is_at_the_torque_limit(backend, moving_speed, torque_limit,
                                                                          overload, commands):
    """A wheel's demand is its output, at most 1.0 = Torque Limit 1023: the check asked for more than the limit, so
    a blocked wheel at full output never overloaded at the factory Torque Limit (at 1022 it did after 0.5 s).
    The drive at its limit (at or above) while stalled is what the e-manual calls a load the set maximum torque
    cannot control; a wheel asked for 60 % of a limit it does not reach is not overloaded."""
    model = PhysicalModel(1, backend=backend)
    model.set_blocked(True)
    cmds = commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=moving_speed, torque_limit=torque_limit)
    assert not model.advance(0.45, cmds).alarms[0] & ALARM_OVERLOAD
    assert bool(model.advance(0.6, cmds).alarms[0] & ALARM_OVERLOAD) == overload


@pytest.mark.parametrize("backend", ["scalar", "numpy"])
def test_a_load_that_turns_the_shaft_back_against_full_drive_overloads(backend, commands):
    """2.5 N m against a servo holding ~1.56 N m turns the shaft back at full drive: never stalled, it never
    overloaded (it ended on Overheating, 132 C).  A shaft turning against a saturated drive is overloaded."""
    model = PhysicalModel(1, backend=backend)
    cmds = commands()
    model.advance(0.3, cmds)
    model.set_external_torque(-2.5)
    sensed = model.advance(1.2, cmds)
    assert model.speed_rad_s[0] < -0.2 and model.drive[0] == 1.0  # turned back, not stalled
    assert sensed.alarms[0] & ALARM_OVERLOAD


def test_a_reversal_at_full_drive_does_not_overload(commands):
    """Full drive while the shaft still turns the old way lasts milliseconds at a reversal: no Overload."""
    model = PhysicalModel(1)
    for k in range(1, 41):
        sensed = model.advance(k * 0.05, commands(goal_position=1000 if (k // 4) % 2 else 20))
        assert not sensed.alarms[0] & ALARM_OVERLOAD, k


def test_alarm_shutdown_acts_on_input_voltage_at_the_first_thermal_event(commands):
    """A supply outside the voltage limits, selected by Alarm Shutdown, cuts the drive within a thermal period."""
    model = PhysicalModel(2)
    model.set_supply_voltage(12.0)
    sensed = model.advance(0.5, commands(2, goal_position=900, max_voltage_limit=110, shutdown=[ALARM_INPUT_VOLTAGE, 0]))
    assert sensed.alarms.tolist() == [ALARM_INPUT_VOLTAGE] * 2 and sensed.output_cut.tolist() == [1, 0]
    assert model.drive[0] == 0.0 and model.drive[1] > 0.0
    assert abs(int(sensed.present_position[0]) - 512) <= 1 and sensed.present_position[1] > 600
