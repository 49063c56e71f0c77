"""Protocol 1.0 packets decoded by the table of the model each ID is (MX, AX-18A), as a trace records the models.

An MX's table differs from the AX-12's past address 24 (PID gains where the compliance margins are,
Goal Acceleration at 73 beyond the AX-12's 50 bytes), so naming its registers by the AX-12 table
would be wrong; the trace's header names every servo's model and the decoder takes each ID's table.
"""

from __future__ import annotations

import json

import serial

import ax12emu  # noqa: F401  (registers the URL handler)
from ax12emu import VirtualBus
from ax12emu.protocol.packets import Instruction, encode_instruction, encode_status
from ax12emu.tracing.decoder import INSTRUCTION, STATUS, Decoder, decode, tables_by_protocol
from ax12emu.tracing.trace import IN, OUT, Chunk, read_trace, trace_header

BAUD = 1_000_000
P_GAIN, GOAL_ACCELERATION, PRESENT_POSITION = 28, 73, 36


def test_a_served_mx_wire_trace_names_each_ids_registers_by_its_model(tmp_path):
    path = tmp_path / "mx.jsonl"
    sent = [
        encode_instruction(1, Instruction.WRITE, bytes([GOAL_ACCELERATION, 20])),
        encode_instruction(1, Instruction.READ, bytes([P_GAIN, 1])),
        encode_instruction(2, Instruction.READ, bytes([P_GAIN, 1])),  # the AX-12A: its CW Compliance Slope
        encode_instruction(0xFE, Instruction.SYNC_WRITE, bytes([P_GAIN, 1, 1, 40, 2, 64])),
    ]
    with VirtualBus(servo="1:mx-28,2:ax-12a,3:xl430-w250", transport="inprocess", baud_bps=BAUD, trace=str(path)) as bus:
        with serial.serial_for_url(bus.port, baudrate=BAUD, timeout=0.5) as link:
            for packet, size in zip(sent, (6, 7, 7, 0)):
                link.write(packet)
                assert len(link.read(size)) == size
        assert bus.read(1, "p_gain") == 40 and bus.read(2, "cw_compliance_slope") == 64
    servos = trace_header(path)["servos"]
    assert servos == "1:mx-28,2:ax-12a,3:xl430-w250"
    decoded = decode(read_trace(path), servos=servos)
    assert [d.raw for d in decoded if d.kind == INSTRUCTION] == sent
    assert [d.text for d in decoded] == [
        "WRITE id=1 goal_acceleration=20",
        "STATUS id=1 ok",
        "READ id=1 address=28 length=1 (p_gain)",
        "STATUS id=1 ok p_gain=32",
        "READ id=2 address=28 length=1 (cw_compliance_slope)",
        "STATUS id=2 ok cw_compliance_slope=32",
        "SYNC_WRITE id=254 [id=1 p_gain=40] [id=2 cw_compliance_slope=64]",
    ]


def test_without_the_models_1_0_registers_fall_back_to_the_profile():
    chunks = [Chunk(0.0, IN, encode_instruction(1, Instruction.WRITE, bytes([GOAL_ACCELERATION, 20]))),
              Chunk(0.001, OUT, encode_status(1, 0))]
    assert decode(chunks)[0].text == "WRITE id=1 [73]=20"  # past the AX-12's table: an address
    assert Decoder(servos="1:mx-64").feed(chunks[0])[0].text == "WRITE id=1 goal_acceleration=20"
    # A 1.0-only wire stays on the 1.0 framer; a model of 2.0 asks for both.
    assert Decoder(servos="1:mx-64").protocol == "1.0"


def test_one_id_has_a_table_on_each_protocol():
    tables = tables_by_protocol("1:mx-106,1:xm430-w350,2:ax-18a", profile="ax12-2006")
    assert tables["1.0"][1].by_name["goal_acceleration"].address == GOAL_ACCELERATION
    assert tables["2.0"][1].by_name["goal_position"].address == 116
    assert "goal_acceleration" not in tables["1.0"][2].by_name  # the AX-18A's own table
    decoded = decode([Chunk(0.0, IN, encode_instruction(1, Instruction.READ, bytes([PRESENT_POSITION, 2])))],
                     servos="1:mx-106,1:xm430-w350")
    assert [(d.kind, d.text) for d in decoded] == [(INSTRUCTION, "READ id=1 address=36 length=2 (present_position)")]
    assert STATUS not in [d.kind for d in decoded]


def test_the_cli_decodes_a_trace_by_its_header(tmp_path, capsys):
    from ax12emu.cli.main import main

    path = tmp_path / "t.jsonl"
    header = {"format": "ax12emu-trace/1", "started": "2026-01-01T00:00:00+00:00", "profile": "ax12a", "servos": "5:mx-28"}
    path.write_text(json.dumps(header) + "\n" + json.dumps(
        {"t": 0.0, "dir": IN, "data": encode_instruction(5, Instruction.WRITE, bytes([GOAL_ACCELERATION, 9])).hex(" ")}) + "\n")
    assert main(["decode", str(path)]) == 0
    assert "WRITE id=5 goal_acceleration=9" in capsys.readouterr().out


def test_a_bulk_read_and_its_replies_are_named_by_each_listed_servos_block(tmp_path):
    path = tmp_path / "bulk.jsonl"
    # MX-28 at ID 1: Present Position (2 bytes); MX-64 at ID 2: P Gain (1 byte), the e-manual's "Bulk Read".
    bulk = encode_instruction(0xFE, Instruction.BULK_READ, bytes([0x00, 2, 1, PRESENT_POSITION, 1, 2, P_GAIN]))
    with VirtualBus(servo="1:mx-28,2:mx-64", transport="inprocess", baud_bps=BAUD, trace=str(path)) as bus:
        with serial.serial_for_url(bus.port, baudrate=BAUD, timeout=0.5) as link:
            link.write(bulk)
            assert len(link.read(8 + 7)) == 15
    decoded = decode(read_trace(path), servos=trace_header(path)["servos"])
    texts = [d.text for d in decoded]
    assert texts[0] == ("BULK_READ id=254 [id=1 address=36 length=2 (present_position)] "
                        "[id=2 address=28 length=1 (p_gain)]")
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS, STATUS]
    assert texts[1].startswith("STATUS id=1 ok present_position=")
    assert texts[2] == "STATUS id=2 ok p_gain=32"


def test_a_bulk_read_reply_with_an_alarm_is_still_a_reply_on_a_raw_capture():
    # No direction recorded: a reply's error byte 0x01 (Input Voltage) is PING's instruction code.
    bulk = encode_instruction(0xFE, Instruction.BULK_READ, bytes([0x00, 2, 1, PRESENT_POSITION, 2, 2, PRESENT_POSITION]))
    chunks = [Chunk(0.0, None, bulk), Chunk(0.001, None, encode_status(1, 0x01, bytes([0, 2]))),
              Chunk(0.002, None, encode_status(2, 0x01, bytes([1, 2]))),
              Chunk(0.003, None, encode_instruction(2, Instruction.PING))]
    decoded = decode(chunks, servos="1:mx-28,2:mx-28")
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS, STATUS, INSTRUCTION]
    assert decoded[1].text == "STATUS id=1 INPUT_VOLTAGE present_position=512"
    assert decoded[2].text == "STATUS id=2 INPUT_VOLTAGE present_position=513"


def test_a_retry_read_after_a_lost_bulk_read_answer_is_the_hosts():
    """On a raw capture the host's READ to the ID whose answer was lost, 50 ms later, has the block's length: it was
    taken for that servo's answer, and the READ vanished from the decode."""
    bulk = encode_instruction(0xFE, Instruction.BULK_READ, bytes([0x00, 2, 1, PRESENT_POSITION, 2, 2, PRESENT_POSITION]))
    retry = encode_instruction(2, Instruction.READ, bytes([PRESENT_POSITION, 2]))
    chunks = [Chunk(0.0, None, bulk), Chunk(0.001, None, encode_status(1, 0, bytes([0, 2]))),
              Chunk(0.050, None, retry), Chunk(0.051, None, encode_status(2, 0, bytes([16, 2])))]
    decoded = decode(chunks, servos="1-2:mx-28")
    assert [d.kind for d in decoded] == [INSTRUCTION, STATUS, INSTRUCTION, STATUS]
    assert decoded[2].text == "READ id=2 address=36 length=2 (present_position)"
