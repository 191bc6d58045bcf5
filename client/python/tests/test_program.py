"""Session.run_program: the server interprets the G-code as `swarf run`
does; arcs sent as arcs give the program's heights bit for bit; an error
names the file and line; a program survives a SIGKILLed server."""

import pathlib
import threading

import grpc
import numpy as np
import pytest

import swarf_client
from swarf_client import Arc, Flat, SwarfError

from conftest import Swarfd

ROOT = pathlib.Path(__file__).resolve().parents[3]
POCKET = ROOT / "examples" / "pocket.nc"
POCKET_TOOLS = {1: Flat(3), 2: Flat(1.5), 3: Flat(0.5)}

# The arcs of test_arcs.py as G-code (G2/G3 with I/J, a helix with P2).
ARC_PROGRAM = """G21 G90 G17
G0 X-10 Y0 Z5
G1 Z-1 F500
G2 X10 Y0 I10 J0
G3 X0 Y10 I-10 J0
G1 X0 Y8 Z-1.5
G2 X0 Y8 Z-3 I0 J-8 P2
G1 X15 Y15 Z-0.5
M2
"""


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float64).view(np.uint64)


def test_program_heights_equal_the_arcs_sent_as_arcs(client):
    stock = (-20, -20, 20, 20, 0)
    with client.create_session(stock, nx=160, ny=160, scheme="guarded",
                               tools={1: 1.5}, delete_on_exit=True) as p, \
         client.create_session(stock, nx=160, ny=160, scheme="guarded",
                               tools={1: 1.5}, delete_on_exit=True) as a:
        seen = []
        done = p.run_program(ARC_PROGRAM, name="arcs.nc", progress=seen.append)
        assert done.first_seq == 1 and done.last_seq >= 1
        assert [ack.seq for ack in seen] == list(range(1, done.last_seq + 1))
        tips = [[-10, 0, 5], [-10, 0, -1], [10, 0, -1], [0, 10, -1],
                [0, 8, -1.5], [0, 8, -3], [15, 15, -0.5]]
        a.send(tips, arcs=[Arc(2, (0, 0, 0), clockwise=True),
                           Arc(3, (0, 0, 0)),
                           Arc(5, (0, 0, 0), clockwise=True, turns=2)])
        assert p.refresh().moves_applied == a.refresh().moves_applied
        assert done.moves == p.moves_applied
        hp, ha = p.heights(owners=True), a.heights(owners=True)
        np.testing.assert_array_equal(bits(hp.z), bits(ha.z))
        np.testing.assert_array_equal(hp.owners, ha.owners)


def test_pocket_program_cuts_its_floors(client):
    with client.create_session((0, 0, 100, 80, 0), spacing=0.5,
                               tools=POCKET_TOOLS, delete_on_exit=True) as s:
        done = s.run_program(POCKET)  # a path: T1..T3 are the tools' ids
        assert done.source_lines > 18000 and done.moves > 18000
        h = s.heights()
        assert h.z.min() == -6 and h.z.max() == 0
        assert h.z[80, 60] == -6       # T1's round pocket at (30, 40)
        assert h.z[80, 152] == -4      # T2's rectangle at (76, 40)
        # Twice on one session: the second program follows the first.
        again = s.run_program(POCKET.read_text(), name="pocket.nc")
        assert again.first_seq == done.last_seq + 1
        np.testing.assert_array_equal(bits(s.heights().z), bits(h.z))


def test_program_errors_name_the_file_and_line(client):
    with client.create_session((0, 0, 10, 10, 0), nx=10, ny=10,
                               tools={1: 1.0, 2: 2.0},
                               delete_on_exit=True) as s:
        with pytest.raises(SwarfError) as e:
            s.run_program("G21 G90\nG0 X1 Y1 Z1\nG1 Z-1 F9\nG1 X2 A3\nM2\n",
                          name="job.nc")
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert e.value.kind == "program"
        assert str(e.value.message).startswith("job.nc: line 4: A axis")
        with pytest.raises(SwarfError) as e:
            s.run_program("G21 G90\nT7 M6\nG0 X1 Y1 Z1\nG1 Z-1 F9\nM2\n")
        assert "program: line 2: T7 has no tool" in e.value.message
        # The map gives T7 a tool; warnings name what swarf run prints.
        done = s.run_program("G90\nT7 M6\nG0 X1 Y1 Z1\nG1 Z-1 F9\nM2\n",
                             tools={7: 2}, name="job.nc")
        assert done.warnings[0].startswith("job.nc: note: no G20/G21")
        # Two batches: the rapid placing the tool, then the feed.
        assert s.refresh().last_seq == done.last_seq == 2
        assert done.moves == s.moves_applied == 1
        with pytest.raises(SwarfError) as e:
            s.run_program("G0 X1\n", dialect="heidenhain")
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT


def test_program_resumes_across_a_killed_server(tmp_path):
    server = Swarfd(tmp_path / "data", ["--journal_sync=full"])
    server.start()
    try:
        c = swarf_client.Client(server.target)
        with c.create_session((0, 0, 100, 80, 0), spacing=0.5,
                              tools=POCKET_TOOLS, delete_on_exit=True) as ref:
            whole = ref.run_program(POCKET, batch_points=300)
            reference = ref.heights().z
        # The server applies the program without waiting for the client to
        # read its acks: on a loaded machine it may have finished when the
        # client reads the third, and the kill then interrupts nothing (no
        # resume). Such a run is still checked, and another session tries
        # again, until one is killed mid-program.
        for attempt in range(5):
            s = c.create_session((0, 0, 100, 80, 0), spacing=0.5,
                                 tools=POCKET_TOOLS,
                                 session_id=f"prog{attempt}")
            restarter = []

            def kill_at_the_third(ack) -> None:
                if ack.seq == 3 and not restarter:
                    server.kill()
                    t = threading.Timer(0.5, server.start)
                    t.start()
                    restarter.append(t)

            done = s.run_program(POCKET, batch_points=300,
                                 progress=kill_at_the_third)
            restarter[0].join()
            assert done.last_seq == whole.last_seq > 3
            assert s.refresh().last_seq == whole.last_seq
            np.testing.assert_array_equal(bits(s.heights().z),
                                          bits(reference))
            if done.resumed >= 1:
                break
        assert done.resumed >= 1
        c.close()
    finally:
        server.stop()
