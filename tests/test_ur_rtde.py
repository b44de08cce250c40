"""RTDE protocol: byte layout, handshake v2 / v1 fallback, recipes, errors, keep-alive, faults, ur-rtde conformance.

Every test talks over real sockets on 127.0.0.1 to the loopback controller. Output
rates are counted on simulated time (a ``clock="stepped"`` controller: N cycles give
exactly N × f / 500 packages of an f Hz recipe), so they hold on a loaded machine.
"""

from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
import time

import pytest

from robocritics.errors import DeployError, RTDEError
from robocritics.deploy import MessageLevel, RTDEClient
from robocritics.testing.ursim import URSim
from robocritics.deploy.rtde import (
    Command,
    Recipe,
    TextMessage,
    decode_text_message,
    encode_text_message,
    pack_package,
)
from ur_support import sim_kwargs, stepped

BIG_RECIPE = (
    ["timestamp", "actual_q", "actual_qd", "target_q", "target_qd", "actual_TCP_pose", "target_TCP_pose"]
    + [f"output_double_register_{i}" for i in range(48)]
    + [f"input_double_register_{i}" for i in range(48)]
)


@pytest.fixture
def sim():
    with URSim(**sim_kwargs()) as s:
        yield s


def packages_after(c: RTDEClient, n: int, timeout_s: float = 2.0) -> int:
    """Wait until ``c`` has received ``n`` packages (then a little longer, to catch extra ones); the count."""
    deadline = time.monotonic() + timeout_s
    while c.packages_received < n and time.monotonic() < deadline:
        time.sleep(0.001)
    time.sleep(0.02)
    return c.packages_received


def _recv_package(sock: socket.socket) -> tuple[int, bytes]:
    head = sock.recv(3, socket.MSG_WAITALL)
    size, cmd = struct.unpack(">HB", head)
    return cmd, sock.recv(size - 3, socket.MSG_WAITALL) if size > 3 else b""


# ---------------------------------------------------------------------------- codec


def test_every_data_type_round_trips_big_endian():
    types = ["BOOL", "UINT8", "UINT32", "INT32", "UINT64", "DOUBLE", "VECTOR3D", "VECTOR6D", "VECTOR6INT32", "VECTOR6UINT32"]
    values = {
        "b": True,
        "u8": 255,
        "u32": 2**32 - 1,
        "i32": -(2**31),
        "u64": 2**64 - 1,
        "d": -1.25e-7,
        "v3": (1.0, -2.0, 3.5),
        "v6": (0.1, 0.2, 0.3, -0.4, -0.5, 6.0),
        "v6i": (-1, 2, -3, 2**31 - 1, -(2**31), 0),
        "v6u": (0, 1, 2, 3, 4, 2**32 - 1),
    }
    recipe = Recipe(3, tuple(values), tuple(types))
    packed = recipe.pack(values)
    expected = struct.pack(
        ">?BIiQd3d6d6i6I", True, 255, 2**32 - 1, -(2**31), 2**64 - 1, -1.25e-7, *values["v3"], *values["v6"], *values["v6i"], *values["v6u"]
    )
    assert packed == expected
    assert recipe.size == len(expected) == 1 + 1 + 4 + 4 + 8 + 8 + 24 + 48 + 24 + 24
    assert recipe.unpack(b"\x03" + packed, 1) == values
    with pytest.raises(RTDEError, match="'u8'.*UINT8"):
        recipe.pack({**values, "u8": 256})
    with pytest.raises(RTDEError, match="missing \\['v6u'\\]"):
        recipe.pack({k: v for k, v in values.items() if k != "v6u"})
    with pytest.raises(RTDEError, match="needs 6 numbers, got 5"):
        recipe.pack({**values, "v6": (1.0,) * 5})


def test_text_message_layouts_v2_and_v1():
    msg = TextMessage("hello", "src", MessageLevel.WARNING)
    v2 = encode_text_message(msg, 2)
    assert v2 == struct.pack(">B5sB3sB", 5, b"hello", 3, b"src", 2)
    assert decode_text_message(v2, 2) == msg
    v1 = encode_text_message(msg, 1)
    assert v1 == b"\x02hello"
    assert decode_text_message(v1, 1) == TextMessage("hello", "", 2)
    with pytest.raises(RTDEError, match="malformed"):
        decode_text_message(b"\x09abc", 2)
    assert pack_package(Command.CONTROL_PACKAGE_START) == b"\x00\x03S"


def test_controller_speaks_the_wire_format_byte_for_byte(sim):
    with socket.create_connection(("127.0.0.1", sim.rtde_port), timeout=2) as s:
        s.sendall(b"\x00\x05V\x00\x02")
        assert s.recv(4, socket.MSG_WAITALL) == b"\x00\x04V\x01"
        s.sendall(b"\x00\x03v")
        assert s.recv(19, socket.MSG_WAITALL) == b"\x00\x13v" + struct.pack(">IIII", 5, 15, 0, 0)
        names = b"timestamp,actual_q,runtime_state"
        s.sendall(struct.pack(">HB", 3 + 8 + len(names), ord("O")) + struct.pack(">d", 250.0) + names)
        assert _recv_package(s) == (ord("O"), b"\x01DOUBLE,VECTOR6D,UINT32")
        s.sendall(b"\x00\x03S")
        assert s.recv(4, socket.MSG_WAITALL) == b"\x00\x04S\x01"
        cmd, payload = _recv_package(s)
        assert cmd == ord("U") and payload[0] == 1 and len(payload) == 1 + 8 + 48 + 4
        ts, *q = struct.unpack_from(">d6d", payload, 1)
        assert tuple(q) == pytest.approx(sim.q, abs=1e-12) and ts > 0
        (runtime,) = struct.unpack_from(">I", payload, 57)
        assert runtime == 1
        s.sendall(b"\x00\x03P")
        while (pkg := _recv_package(s))[0] == ord("U"):
            pass
        assert pkg == (ord("P"), b"\x01")


def test_protocol_v1_layout_has_no_frequency_and_no_output_recipe_id(sim):
    with socket.create_connection(("127.0.0.1", sim.rtde_port), timeout=2) as s:
        s.sendall(b"\x00\x05V\x00\x01")
        assert s.recv(4, socket.MSG_WAITALL) == b"\x00\x04V\x01"
        names = b"timestamp,safety_mode"
        s.sendall(struct.pack(">HB", 3 + len(names), ord("O")) + names)  # v1: names only
        assert _recv_package(s) == (ord("O"), b"DOUBLE,INT32")  # v1: types only
        s.sendall(b"\x00\x03S")
        assert s.recv(4, socket.MSG_WAITALL) == b"\x00\x04S\x01"
        cmd, payload = _recv_package(s)
        assert cmd == ord("U") and len(payload) == 8 + 4  # no recipe id byte
        assert struct.unpack(">di", payload)[1] == 1  # NORMAL
        sim.broadcast_message("v1 text", MessageLevel.INFO)
        while (pkg := _recv_package(s))[0] == ord("U"):
            pass
        assert pkg == (ord("M"), b"\x03v1 text")  # v1: level byte, then the text


# ---------------------------------------------------------------------------- handshake


def test_handshake_negotiates_v2_and_reports_controller_version():
    with URSim(**stepped()) as sim, RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        assert c.protocol_version == 2
        assert c.controller_version == (5, 15, 0, 0)
        assert c._sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
        assert c._sock.gettimeout() == 1.0
        recipe = c.setup_outputs(["timestamp", "actual_q"], frequency_hz=250)
        assert recipe.recipe_id == 1 and recipe.types == ("DOUBLE", "VECTOR6D")
        c.start()
        sim.step(500)  # 1 s of controller time
        assert packages_after(c, 251) == 251  # 250 Hz requested: the first cycle after start, then every other one
        stamps = [p["timestamp"] for p in c.drain()]
        assert stamps == pytest.approx([0.002] + [0.004 * (k + 1) for k in range(250)])
        assert c.latest()["actual_q"] == pytest.approx(sim.q)


def test_falls_back_to_protocol_v1_on_old_firmware():
    with URSim(**stepped(protocol_versions=(1,), controller_version=(3, 4, 5, 100))) as sim:
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
            assert c.protocol_version == 1
            assert c.controller_version == (3, 4, 5, 100)
            recipe = c.setup_outputs(["timestamp", "actual_q", "input_int_register_30"], frequency_hz=500)
            assert recipe.recipe_id == 0 and recipe.frequency_hz == 125.0  # v1 carries no id and no frequency
            c.setup_inputs(["input_int_register_30"])
            c.start()
            sim.step(400)
            assert packages_after(c, 101) == 101  # fixed 125 Hz: the first cycle after start, then every 4th
            c.send({"input_int_register_30": -42})  # one input package: one cycle
            sim.step(3)
            c.wait_for(lambda s: s["input_int_register_30"] == -42, 1.0, "the v1 input to echo")
            sim.broadcast_message("old firmware says hi", MessageLevel.WARNING)
            deadline = time.monotonic() + 1.0
            while not (msgs := c.messages()) and time.monotonic() < deadline:
                time.sleep(0.01)
            assert msgs and msgs[0].message == "old firmware says hi" and msgs[0].level == MessageLevel.WARNING


def test_no_common_protocol_version_is_a_typed_error():
    with URSim(**sim_kwargs(protocol_versions=(3,))) as sim:
        with pytest.raises(RTDEError, match="accepted none of protocol versions 2, 1"):
            RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0).connect()


# ---------------------------------------------------------------------------- recipes


def test_inputs_and_outputs_of_every_type_round_trip_through_the_controller():
    extra = {
        "test_uint64": "UINT64",
        "test_vector3d": "VECTOR3D",
        "test_vector6d": "VECTOR6D",
        "test_vector6int32": "VECTOR6INT32",
        "test_vector6uint32": "VECTOR6UINT32",
    }
    with URSim(**sim_kwargs(extra_inputs=extra)) as sim:
        sim.write_output_register("bit", 64, True)
        sim.write_output_register("int", 40, -7)
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
            inputs = {
                "input_bit_register_70": True,  # BOOL
                "standard_digital_output_mask": 0b101,  # UINT8
                "standard_digital_output": 0b111,  # UINT8
                "speed_slider_mask": 1,  # UINT32
                "speed_slider_fraction": 0.25,  # DOUBLE
                "input_int_register_31": -123456,  # INT32
                "test_uint64": 2**63 + 5,
                "test_vector3d": (1.5, -2.5, 3.25),
                "test_vector6d": (0.1, 0.2, 0.3, 0.4, 0.5, 0.6),
                "test_vector6int32": (-1, -2, 3, 4, -(2**31), 2**31 - 1),
                "test_vector6uint32": (1, 2, 3, 4, 5, 2**32 - 1),
            }
            rec = c.setup_inputs(list(inputs))
            assert rec.types == (
                "BOOL", "UINT8", "UINT8", "UINT32", "DOUBLE", "INT32", "UINT64", "VECTOR3D", "VECTOR6D", "VECTOR6INT32", "VECTOR6UINT32",
            )
            outputs = [
                "input_bit_register_70", "actual_digital_output_bits", "speed_scaling", "input_int_register_31",
                *list(extra), "output_bit_register_64", "output_int_register_40", "joint_mode", "tool_output_mode",
                "actual_tool_accelerometer", "runtime_state",
            ]
            out = c.setup_outputs(outputs, 500)
            assert out.types[:2] == ("BOOL", "UINT64")
            assert out.types[-5:] == ("INT32", "VECTOR6INT32", "UINT8", "VECTOR3D", "UINT32")
            c.start()
            c.send(inputs)
            st = c.wait_for(lambda s: s["input_int_register_31"] == -123456, 1.0, "inputs to echo")
            assert st["input_bit_register_70"] is True
            assert st["actual_digital_output_bits"] == 0b101  # only masked bits set
            assert st["speed_scaling"] == 0.25
            for name in extra:
                assert st[name] == inputs[name], name
            assert st["output_bit_register_64"] is True and st["output_int_register_40"] == -7
            assert st["joint_mode"] == (253,) * 6 and st["tool_output_mode"] == 0
            assert st["runtime_state"] == 1
            with pytest.raises(RTDEError, match="match no input recipe"):
                c.send({"input_int_register_31": 1})


def test_unknown_fields_are_named_as_not_found(sim):
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        with pytest.raises(RTDEError) as err:
            c.setup_outputs(["actual_q", "actual_q_filtered", "output_int_register_48"], 125)
        text = str(err.value)
        assert "'actual_q_filtered'" in text and "'output_int_register_48'" in text and "'actual_q'," not in text
        assert "NOT_FOUND" in text and "doesn't know" in text and "older firmware" in text
        with pytest.raises(RTDEError, match="'input_double_register_99'.*NOT_FOUND"):
            c.setup_inputs(["input_double_register_24", "input_double_register_99"])
        # the failed setups left nothing behind: a correct recipe still works
        assert c.setup_outputs(["actual_q"], 125).recipe_id >= 1


def test_fieldbus_registers_are_in_use():
    with URSim(**sim_kwargs(fieldbus_registers=True)) as sim:
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
            with pytest.raises(RTDEError) as err:
                c.setup_inputs(["input_int_register_24", "input_int_register_3"])
            assert "'input_int_register_3'" in str(err.value) and "'input_int_register_24'" not in str(err.value)
            assert "IN_USE" in str(err.value) and "24-47" in str(err.value) and "stop the other client" in str(err.value)
            assert c.setup_inputs(["input_int_register_24"]).types == ("INT32",)


def test_input_held_by_another_client_is_in_use_until_it_disconnects(sim):
    a = RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0)
    a.connect()
    a.setup_inputs(["input_double_register_24", "input_int_register_24"])
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as b:
        with pytest.raises(RTDEError, match="'input_double_register_24'.*IN_USE"):
            b.setup_inputs(["input_double_register_24"])
        assert b.setup_inputs(["input_double_register_25"]).recipe_id > 0  # others stay free
        a.close()
        deadline = time.monotonic() + 1.0
        while True:
            try:
                b.setup_inputs(["input_double_register_24"])
                break
            except RTDEError:
                assert time.monotonic() < deadline, "ownership not released after the other client left"
                time.sleep(0.02)


def test_text_messages_both_directions(sim):
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        c.send_message("deploying trajectory 3f2a", source="robocritics", level=MessageLevel.INFO)
        sim.broadcast_message("controller note", MessageLevel.ERROR, source="URSim")
        deadline = time.monotonic() + 1.0
        got = []
        while time.monotonic() < deadline and not (got and sim.events("client_message")):
            got += c.messages()
            time.sleep(0.01)
        assert got == [TextMessage("controller note", "URSim", MessageLevel.ERROR)]
        (ev,) = sim.events("client_message")
        assert "[robocritics] INFO: deploying trajectory 3f2a" in ev.message


def test_pause_stops_data_and_start_resumes(sim):
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        c.setup_outputs(["timestamp"], 500)
        c.start()
        first = c.wait_next(1.0)["timestamp"]
        c.pause()
        n = c.packages_received
        time.sleep(0.1)
        assert c.packages_received == n
        with pytest.raises(RTDEError, match="call start"):
            c.wait_next(0.1)
        c.start()
        assert c.wait_next(1.0)["timestamp"] > first + 0.09
        buffered = c.drain()
        assert buffered and all(set(p) == {"timestamp"} for p in buffered)


# ---------------------------------------------------------------------------- keep-alive and faults


def test_reader_thread_keeps_the_connection_alive_while_the_user_does_not_read():
    with URSim(**sim_kwargs(slow_client_timeout_s=0.2)) as sim:
        # A client that stops reading is dropped by the controller…
        raw = socket.create_connection(("127.0.0.1", sim.rtde_port), timeout=2)
        raw.sendall(pack_package(Command.REQUEST_PROTOCOL_VERSION, b"\x00\x02"))
        assert _recv_package(raw) == (ord("V"), b"\x01")
        raw.sendall(pack_package(Command.CONTROL_PACKAGE_SETUP_OUTPUTS, struct.pack(">d", 500) + ",".join(BIG_RECIPE).encode()))
        assert _recv_package(raw)[1][0] == 1
        raw.sendall(pack_package(Command.CONTROL_PACKAGE_START))
        t0 = time.monotonic()
        while not sim.events("rtde_closed") and time.monotonic() - t0 < 5:
            time.sleep(0.01)
        dropped_after = time.monotonic() - t0
        (ev,) = sim.events("rtde_closed")
        assert "not reading" in ev.message
        raw.close()
        # …ours is not, even if the user ignores it for more than twice as long.
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
            c.setup_outputs(BIG_RECIPE, 500)
            c.start()
            sent_before = sim.packages_sent
            idle = max(1.0, 2 * dropped_after)
            time.sleep(idle)
            assert c.connected and len(sim.events("rtde_closed")) == 1
            # the reader kept up with whatever rate the controller managed (a loaded host slows both)
            sent = sim.packages_sent - sent_before
            assert sent > 50 and c.packages_received >= sent - 50
            st = c.latest()
            assert sim.snapshot().time_s - st["timestamp"] < 0.5  # fresh, not a stale backlog of the idle time
            assert c.wait_next(0.5)["timestamp"] > st["timestamp"]


def test_connection_drop_gives_a_typed_error_in_bounded_time(sim):
    c = RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0)
    c.connect()
    c.setup_outputs(["timestamp", "actual_q"], 500)
    c.setup_inputs(["input_int_register_24"])
    c.start()
    c.wait_next(1.0)
    sim.inject_drop(after_packages=50)
    t0 = time.monotonic()
    with pytest.raises(RTDEError) as err:
        while time.monotonic() - t0 < 3:
            c.wait_next(0.5)
    assert time.monotonic() - t0 < 1.0
    text = str(err.value)
    assert f"127.0.0.1:{sim.rtde_port}" in text and "closed by the controller" in text and "streaming" in text
    assert "data packages" in text
    assert not c.connected
    with pytest.raises(RTDEError, match="closed by the controller"):
        c.send({"input_int_register_24": 1})
    with pytest.raises(RTDEError, match="closed by the controller"):
        c.latest()
    assert c.latest(allow_stale=True)["actual_q"] == pytest.approx(sim.q)  # where the robot was, for the report
    c.close()


def test_silent_controller_times_out_with_a_typed_error(sim):
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=0.3) as c:
        c.setup_outputs(["timestamp"], 500)
        c.start()
        c.wait_next(1.0)
        sim.set_silent(rtde=True)
        time.sleep(0.02)
        c.drain()
        t0 = time.monotonic()
        with pytest.raises(RTDEError, match=r"no RTDE data package from 127\.0\.0\.1:\d+ within 0\.2 s"):
            while True:  # packages already in flight may still arrive
                c.wait_next(0.2)
        assert time.monotonic() - t0 < 0.6
        with pytest.raises(RTDEError, match=r"no reply to 'P' \(pause\).*within 0\.3 s"):
            c.pause()
        assert c.age_s() > 0.2
        with pytest.raises(RTDEError, match="no reply to 'P'"):  # the conversation is out of sync: stay failed
            c.latest()


def test_slow_controller_sends_at_a_lower_rate_and_replies_late():
    with URSim(**stepped()) as sim, RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=0.2) as c:
        sim.set_slow(output_rate_factor=0.5)
        c.setup_outputs(["timestamp"], 500)
        c.start()
        sim.step(400)
        assert packages_after(c, 201) == 201  # half of 500 Hz: the first cycle after start, then every other one
        sim.set_slow(reply_delay_s=0.4)
        with pytest.raises(RTDEError, match="no reply to 'O' \\(setup outputs\\)"):
            c.setup_outputs(["actual_q"], 125)


def test_connect_to_a_closed_port_is_a_typed_error():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    t0 = time.monotonic()
    with pytest.raises(RTDEError, match=f"cannot connect to RTDE at 127.0.0.1:{port}"):
        RTDEClient("127.0.0.1", port, timeout_s=1.0).connect()
    assert time.monotonic() - t0 < 1.0


def test_client_validates_before_sending(sim):
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        with pytest.raises(RTDEError, match="frequency must be in"):
            c.setup_outputs(["actual_q"], 1000)
        with pytest.raises(RTDEError, match="more than once"):
            c.setup_outputs(["actual_q", "actual_q"], 125)
        with pytest.raises(RTDEError, match="setup_outputs\\(\\) before start"):
            c.start()


# ---------------------------------------------------------------------------- conformance with ur-rtde

_UR_RTDE_CLIENT = r"""
import json, sys, time
import rtde_receive, dashboard_client
r = rtde_receive.RTDEReceiveInterface("127.0.0.1")
deadline = time.time() + 2
while r.getTimestamp() == 0.0 and time.time() < deadline:
    time.sleep(0.01)
out = dict(q=r.getActualQ(), t=r.getTimestamp(), mode=r.getRobotMode(), safety=r.getSafetyMode(),
           runtime=r.getRuntimeState(), pose=r.getActualTCPPose(), connected=r.isConnected())
r.disconnect()
d = dashboard_client.DashboardClient("127.0.0.1")
d.connect()
out["remote"] = d.isInRemoteControl()
out["robotmode"] = str(d.robotmode())
out["safetystatus"] = str(d.safetystatus())
d.disconnect()
print(json.dumps(out))
"""


def test_conformance_with_the_ur_rtde_client():
    pytest.importorskip("rtde_receive", reason="ur-rtde is not installed")
    q0 = (0.3, -1.1, 1.4, -0.2, 0.7, -2.5)
    check_dashboard = True
    try:
        sim = URSim(initial_q=q0, secondary_port=0).start()  # real RTDE and dashboard ports
    except DeployError:
        check_dashboard = False  # 29999 may be taken; the RTDE part only needs 30004
        try:
            sim = URSim(initial_q=q0, dashboard_port=0, secondary_port=0).start()
        except DeployError as exc:
            pytest.skip(f"port 30004 is taken, cannot run the ur-rtde conformance test (ur-rtde always uses it): {exc}")
    script = _UR_RTDE_CLIENT if check_dashboard else _UR_RTDE_CLIENT.split("d = dashboard_client")[0] + "print(json.dumps(out))\n"
    try:
        # ur-rtde's constructor holds the GIL while it waits for replies, so it runs in its own process.
        proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=20)
        assert proc.returncode == 0, proc.stderr[-2000:]
        out = json.loads(proc.stdout.strip().splitlines()[-1])
    finally:
        sim.stop()
    assert len(out["q"]) == 6
    assert max(abs(a - b) for a, b in zip(out["q"], q0)) < 1e-6
    assert out["connected"] and out["t"] > 0
    assert (out["mode"], out["safety"], out["runtime"]) == (7, 1, 1)
    from robocritics.testing.ursim.controller import ur3e_fk

    assert out["pose"] == pytest.approx(ur3e_fk(q0)[0], abs=1e-9)
    if check_dashboard:
        assert out["remote"] is True
        assert out["robotmode"] == "Robotmode: RUNNING" and out["safetystatus"] == "Safetystatus: NORMAL"
    assert len(sim.events("rtde_connected")) == 1
