"""Plant: command registers out of the tables, sensed values back into them, alarms applied."""

import pytest

from ax12emu.bus.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.servo.model_factory import ModelChoice, build_model
from firmware_model.interface import Sensed
from firmware_model.units import RAD_PER_POSITION_UNIT

SENSED = [name for name in Sensed.field_names() if name not in ("alarms", "output_cut")]


def _step(bus: Bus, steps: int = 1) -> None:
    for _ in range(steps):
        bus.clock.advance(0.001)
        bus.advance()


def _mixed_bus() -> Bus:
    bus = Bus([1, 2, 3], clock=VirtualClock())
    wheel, mover, _ = (servo.table for servo in bus.servos)
    for table in (wheel, mover):
        table.set("torque_enable", 1)
    wheel.set("cw_angle_limit", 0)
    wheel.set("ccw_angle_limit", 0)
    wheel.set("moving_speed", 500)
    mover.set("goal_position", 900)
    bus.plant.tables_changed()
    return bus


def _wheel_bus() -> Bus:
    bus = Bus([1, 2], clock=VirtualClock())
    for servo in bus.servos:
        for name, value in (("cw_angle_limit", 0), ("ccw_angle_limit", 0), ("moving_speed", 400), ("torque_enable", 1)):
            servo.table.set(name, value)
    bus.plant.tables_changed()
    return bus


@pytest.mark.parametrize("make_bus", [_mixed_bus, _wheel_bus], ids=["wheel, joint, idle", "all wheels driven"])
def test_tables_hold_what_the_model_senses_after_every_step(make_bus):
    """Every sensed register of every servo equals the model's reading after each step (also when a
    register keeps its value and the plant need not copy it again: slow registers, a driven wheel's Moving)."""
    bus = make_bus()
    first, second = (servo.table for servo in bus.servos[:2])
    positions = set()
    for step in range(400):
        _step(bus)
        sensed = bus.model.sense()
        positions.add((first.get("present_position"), second.get("present_position")))
        for index, servo in enumerate(bus.servos):
            for name in SENSED:
                assert servo.table.get(name) == getattr(sensed, name)[index], (step, servo.id, name)
            assert servo.alarms == sensed.alarms[index] & 0x7F
    assert len(positions) > 100  # they did move


@pytest.mark.parametrize("announce", ["tables_changed", "refresh"])
def test_a_sensed_register_overwritten_by_someone_else_is_rewritten_once_they_say_so(announce):
    """A writer other than the plant (a test, a fault) announces it; the next step then restores the
    model's value even if the model's reading itself did not change."""
    bus = Bus([1], clock=VirtualClock())
    _step(bus)
    table = bus.servos[0].table
    true_c = table.get("present_temperature")
    table.set("present_temperature", true_c + 20)
    getattr(bus.plant, announce)()
    _step(bus)
    assert table.get("present_temperature") == true_c


def test_a_step_in_pieces_ends_where_a_whole_step_does_and_shows_the_old_one_until_then():
    """The serving loop's pieces (step, read the sensors, write them back): the tables keep the
    previous step's values until the last piece, then equal what a whole step writes."""
    whole, pieces = _wheel_bus(), _wheel_bus()
    for step in range(300):
        for bus in (whole, pieces):
            bus.clock.advance(0.001)
        whole.advance()
        before = pieces.rows.copy()
        run = pieces.advance_in_pieces()
        next(run)
        assert (pieces.rows == before).all(), step
        for _ in run:
            pass
        assert (pieces.rows == whole.rows).all(), step
    assert whole.servos[0].table.get("present_position") != 512  # they did turn


def test_pieces_overtaken_by_a_step_in_the_request_path_do_not_write_older_values():
    """A request that finds physics behind steps it at once and writes the tables; the pieces of the
    step under way then leave them alone rather than put the older readings back."""
    bus = _wheel_bus()
    _step(bus, 50)
    bus.clock.advance(0.001)
    run = bus.advance_in_pieces()
    next(run)
    next(run)  # stepped and sensed, not yet written back
    bus.clock.advance(0.005)
    bus.plant.advance(bus.clock.now_s())  # as Bus.dispatch does when physics lags
    newer = bus.rows.copy()
    for _ in run:
        pass
    assert (bus.rows == newer).all()


def test_pieces_do_not_undo_a_refresh_made_in_between():
    """A shaft turned by hand (the model changed, the tables refreshed) between reading the sensors and
    writing them back: the older readings are dropped, the tables keep the new position."""
    bus = _wheel_bus()
    bus.servos[1].table.set("torque_enable", 0)
    bus.plant.tables_changed()
    _step(bus, 5)
    bus.clock.advance(0.001)
    run = bus.advance_in_pieces()
    next(run)
    next(run)  # stepped and sensed, not yet written back
    bus.model.set_angle(1, 100 * RAD_PER_POSITION_UNIT)
    bus.plant.refresh()
    for _ in run:
        pass
    assert bus.servos[1].table.get("present_position") == 100 == bus.model.sense().present_position[1]


def test_a_model_without_step_to_is_stepped_whole():
    """step_to is optional for a model: without it the pieces are one whole step."""

    class WholeStepsOnly:
        def __init__(self, model):
            self._model = model

        def __getattr__(self, name):
            if name == "step_to":
                raise AttributeError(name)
            return getattr(self._model, name)

    bus = Bus([1], model=WholeStepsOnly(build_model(ModelChoice(), 1)), clock=VirtualClock())
    bus.clock.advance(0.005)
    assert list(bus.advance_in_pieces()) == []
    assert bus.model.time_s == pytest.approx(0.005)


def test_each_millisecond_step_of_virtual_time_steps_the_ax_model():
    """After a long step the clock's float sum sits a hair under the model's next step: the test for a whole step
    due skipped every other 1 ms step, and Present Position read 1 ms apart repeated in pairs mid-move."""
    from ax12emu.harness.virtual_bus import VirtualBus
    from ax12emu.protocol.packets import encode_instruction

    with VirtualBus(ids=[1], transport="inprocess", virtual_time=True) as vb:
        vb.write(1, "torque_enable", 1)
        vb.step(1.0)
        vb.bus.answer(encode_instruction(1, 3, bytes([30, 0xFF, 0x03])))  # Goal Position 1023, full speed
        vb.step(0.1)
        positions = []
        for _ in range(12):
            vb.step(0.001)
            data = vb.bus.answer(encode_instruction(1, 2, bytes([36, 2])))[0][0].data[5:-1]
            positions.append(data[0] | data[1] << 8)
    assert all(b > a for a, b in zip(positions, positions[1:])), positions  # at full speed: 1-2 units a millisecond


def _stalled_bus(profile: str | None = None) -> Bus:
    """One servo, torque on, its shaft held while the goal is 288 units away: Overload after the model's delay."""
    from ax12emu.servo.virtual_servo import ServoOptions

    options = ServoOptions() if profile is None else ServoOptions(profile=profile)
    bus = Bus([1], options=options, clock=VirtualClock())
    table = bus.servos[0].table
    table.set("shutdown", 0x20)  # Overload (the 2006 edition's default selects Overheating alone)
    table.set("torque_enable", 1)
    table.set("goal_position", 800)
    bus.model.set_blocked([True])
    bus.plant.tables_changed()
    return bus


@pytest.mark.parametrize("pieces", [1, 6, 600], ids=["60 s at once", "10 s pieces", "0.1 s pieces"])
def test_alarm_shutdown_cuts_the_output_at_the_control_step_however_the_bus_is_stepped(pieces):
    """A stalled servo stepped 60 s at once ran at full drive the whole minute (83 C, Overheating) while the same
    minute in 0.1 s pieces ended at 30 C: Alarm Shutdown acted only when readings were copied back to the table
    (e-manual, Alarm Shutdown: "the motor output becomes 0 % by resetting the value of Torque Limit(34) to 0")."""
    bus = _stalled_bus()
    for _ in range(pieces):
        bus.clock.advance(60.0 / pieces)
        bus.advance()
    table = bus.servos[0].table
    assert table.get("torque_limit") == 0
    assert bus.model.temperature_c[0] < 31.0  # half a second of stall current, then nothing
    assert table.get("present_temperature") == 30 and bus.servos[0].alarms == 0x20
    assert bus.model.drive[0] == 0.0


def test_alarm_shutdown_of_the_2006_edition_turns_torque_off_at_the_control_step():
    """The 2006 manual's edition clears Torque Enable; the output is cut at the step the alarm is found."""
    bus = _stalled_bus("ax12-2006")
    bus.clock.advance(60.0)
    bus.advance()
    table = bus.servos[0].table
    assert table.get("torque_enable") == 0 and table.get("torque_limit") == 1023
    assert bus.model.temperature_c[0] < 31.0


def test_a_torque_limit_written_after_the_cut_drives_the_servo_again():
    """The cut is the table's from the step it is written: a client restoring Torque Limit before the next step
    drives again (for the overload delay, judged afresh, before the alarm cuts it once more), however long the
    step that cut it."""
    bus = _stalled_bus()
    bus.clock.advance(10.0)
    bus.advance()
    table = bus.servos[0].table
    assert table.get("torque_limit") == 0
    table.set("torque_limit", 1023)
    bus.clock.advance(0.3)
    bus.advance()
    assert table.get("torque_limit") == 1023 and bus.model.drive[0] == 1.0 and bus.servos[0].alarms == 0
    bus.clock.advance(0.3)
    bus.advance()
    assert table.get("torque_limit") == 0 and bus.servos[0].alarms == 0x20


@pytest.mark.parametrize("writer", [1, 2], ids=["its own goal", "another servo's goal"])
def test_a_goal_written_between_a_ticks_pieces_leaves_the_cut_in_place(writer):
    """Served in pieces (step, sense, write back), a control loop's Goal Position write and read landing after the
    step that cut the output dropped the cut: any change to the commands ended it, and Torque Limit, 'raised' from
    the cut's 0 back to 1023, restarted the overload timer.  The client read Torque Limit 1023 and error 0x00, and
    the blocked servo drove on at full power for another overload delay.  Only its own Torque Limit, Torque Enable
    or Alarm Shutdown ends a servo's cut."""
    from ax12emu.protocol.packets import encode_instruction
    from ax12emu.servo.virtual_servo import ServoOptions

    bus = Bus([1, 2], clock=VirtualClock(), options=ServoOptions(eeprom_busy_s_per_byte=0.0))
    for servo in bus.servos:
        servo.table.set("shutdown", 0x20)
        servo.table.set("torque_enable", 1)
        servo.table.set("goal_position", 900)
    bus.model.set_blocked([True, False])
    bus.plant.tables_changed()
    for _ in range(2000):
        bus.clock.advance(0.001)
        pieces = bus.advance_in_pieces()
        next(pieces, None)  # the control step
        if bus.model.sense().output_cut[0]:
            break
        for _ in pieces:
            pass
    else:
        raise AssertionError("never cut")
    bus.receive(encode_instruction(writer, 3, bytes([30, 0x85, 0x03])))  # Goal Position 901
    status = bus.receive(encode_instruction(1, 2, bytes([34, 2])))[0].data  # read Torque Limit
    assert (status[4], status[5] | status[6] << 8) == (0x20, 0)
    for _ in pieces:
        pass
    assert bus.servos[0].table.get("torque_limit") == 0 and bus.model.drive[0] == 0.0
    _step(bus, 100)
    assert bus.servos[0].table.get("torque_limit") == 0 and bus.servos[0].alarms == 0x20 and bus.model.drive[0] == 0.0


def test_alarm_shutdown_acts_at_the_control_step_on_a_wire_of_several_models():
    """AX-12A beside AX-18A (one physical model per group, joined): each stalled servo's cut is the step's."""
    from ax12emu.protocol.servo_models import model
    from ax12emu.servo.model_factory import build_protocol1_model
    from firmware_model.grouped import GroupedModel

    keys = ["ax-12a", "ax-18a"]
    layouts = [None if key == "ax-12a" else model(key).layout() for key in keys]
    bus = Bus([1, 2], clock=VirtualClock(), model=build_protocol1_model(keys), table_layout=layouts)
    assert isinstance(bus.model, GroupedModel)
    for servo in bus.servos:
        servo.table.set("torque_enable", 1)
        servo.table.set("goal_position", 800)
    bus.model.set_blocked([True, True])
    bus.plant.tables_changed()
    bus.clock.advance(60.0)
    bus.advance()
    assert [servo.table.get("torque_limit") for servo in bus.servos] == [0, 0]
    assert all(bus.model.sense().present_temperature <= 31)
    bus.servos[0].table.set("torque_limit", 1023)  # written before the next step: the client's, not the cut's
    bus.clock.advance(0.2)
    bus.advance()
    assert [servo.table.get("torque_limit") for servo in bus.servos] == [1023, 0]




@pytest.mark.parametrize("pieces", [1, 120], ids=["120 s at once", "1 s pieces"])
def test_the_2006_editions_cut_is_torque_off_inside_a_long_step_too(pieces):
    """2006 profile (Alarm Shutdown turns torque off), Overheating selected, a blocked servo at full drive: stepped
    in one 120 s piece the model's cut was Torque Limit 0 with torque on, which the overload rule counts, and the
    servo read Overload (0x20) that 1 s pieces (Torque Enable 0 written at the cut) did not."""
    from ax12emu.servo.virtual_servo import ServoOptions

    bus = Bus([1], options=ServoOptions(profile="ax12-2006"), clock=VirtualClock())
    table = bus.servos[0].table
    table.set("shutdown", 0x04)
    table.set("torque_enable", 1)
    table.set("goal_position", 900)
    bus.model.set_blocked([True])
    bus.plant.tables_changed()
    for _ in range(pieces):
        bus.clock.advance(120.0 / pieces)
        bus.advance()
    assert table.get("torque_enable") == 0 and bus.servos[0].alarms == 0


def test_a_model_built_for_another_edition_than_the_tables_is_refused():
    """The bus set the 2006 edition's cut into a model built for the e-manual's, after building it; now the model is
    built for the tables' profile by every route, and one built for another edition is a ValueError naming the fix."""
    from ax12emu.servo.virtual_servo import ServoOptions
    from firmware_model import PhysicalModel

    options = ServoOptions(profile="ax12-2006")
    with pytest.raises(ValueError, match=r"clears torque_limit, these servos' clears torque_enable"):
        Bus([1], options=options, model=PhysicalModel(1))
    assert Bus([1], options=options).model.shutdown_clears == "torque_enable"
    with pytest.raises(AttributeError):
        PhysicalModel(1).shutdown_clears = "torque_enable"  # fixed when built


def test_the_default_model_cuts_as_the_bus_tables_do_whatever_the_profile():
    """A bus of AX-18A tables under the 2006 profile: the AX-18A's table is its model file's (Torque Limit 0), and
    the bus built its default model for the profile (torque off), then refused its own model."""
    from ax12emu.protocol.servo_models import model
    from ax12emu.servo.virtual_servo import ServoOptions

    bus = Bus([1], options=ServoOptions(profile="ax12-2006"), table_layout=model("ax-18a").layout())
    assert bus.model.shutdown_clears == "torque_limit"
