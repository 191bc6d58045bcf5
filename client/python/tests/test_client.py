"""swarf_client against a real swarfd: bit-for-bit heights against the
core (`swarf table --heights`), resume across a killed and restarted
server, every error path, and messages past gRPC's 4 MiB default."""

import pathlib
import subprocess
import sys
import threading
import time

import grpc
import numpy as np
import pytest

import swarf_client
from swarf_client import SwarfError

from conftest import Swarfd, require_shared

FIVE_BALLS = [(50, 50), (30, 30), (70, 30), (30, 70), (70, 70)]


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float64).view(np.uint64)


@pytest.fixture(scope="module")
def five_balls_reference(swarf_cli: str, tmp_path_factory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("table")
    subprocess.run([swarf_cli, "table", "--instance", "five-balls", "--mesh",
                    "100", "--runs", "1", "--heights", str(out)],
                   check=True, stdout=subprocess.DEVNULL)
    return out


@pytest.mark.parametrize("scheme", ["taylor", "zmap"])
def test_five_balls_equal_the_core_bit_for_bit(client, five_balls_reference,
                                                scheme):
    ref = np.load(five_balls_reference / f"five-balls-100-{scheme}.npy")
    assert ref.shape == (101, 101)
    with client.create_session((0, 0, 100, 100, 0), nx=100, ny=100,
                               scheme=scheme, tools={1: 20.0},
                               delete_on_exit=True) as s:
        for cx, cy in FIVE_BALLS:
            # A vertical plunge, tip z +5 -> -10, placed anew each time.
            s.send([[cx, cy, 5], [cx, cy, -10]], reposition=True)
        h = s.heights()
        assert h.z.shape == (101, 101) and h.z.dtype == np.float64
        np.testing.assert_array_equal(bits(h.z), bits(ref))
        assert h.z.min() < -9  # really cut: the ball's bottom
        np.testing.assert_array_equal(h.x, np.arange(101.0))
        np.testing.assert_array_equal(h.y, np.arange(101.0))
        # A region gives the same nodes, and owners are the plunges.
        part = s.heights(region=(20, 25, 60.5, 75), owners=True)
        np.testing.assert_array_equal(bits(part.z), bits(ref[25:76, 20:61]))
        np.testing.assert_array_equal(part.x, np.arange(20.0, 61.0))
        assert set(np.unique(part.owners)) <= {-1, 0, 1, 2, 3, 4}
        assert part.owners[50 - 25, 50 - 20] == 0
        # Edges on tile boundaries (node 64 starts tile 1) and a point.
        edge = s.heights(region=(64, 0, 100, 64))
        np.testing.assert_array_equal(bits(edge.z), bits(ref[0:65, 64:101]))
        one = s.heights(region=(63.5, 64, 64.5, 64))
        np.testing.assert_array_equal(bits(one.z), bits(ref[64:65, 64:65]))
        # float32 heights are the doubles rounded.
        f = s.heights(precision="float")
        np.testing.assert_array_equal(f.z, ref.astype(np.float32))
        stats = s.error_stats(map=(10, 10))
        assert stats.scheme == scheme and stats.samples > 0
        assert stats.map is not None and stats.map.shape == (10, 10)
        assert 0 < stats.max_error == pytest.approx(float(stats.map.max()))
        p = s.probe([[50, 50], [0, 0]])
        assert p.heights[0] == pytest.approx(-10, abs=1e-6)
        assert p.heights[1] == 0 and list(p.owners) == [0, -1]
        assert np.linalg.norm(p.normals[0]) == pytest.approx(1)
        if scheme == "taylor":  # the ball's bottom, exactly; zmap: bilinear
            np.testing.assert_allclose(p.normals[0], [0, 0, 1], atol=1e-6)
        else:
            assert p.normals[0][2] > 0.99
        if scheme == "taylor":
            j = s.jets()
            np.testing.assert_array_equal(bits(j.w), bits(ref))
            assert j.wxx.dtype == np.float32 and j.wxx.shape == (101, 101)
            marks = s.marks()
            assert marks, "five balls meet along creases"
            for m in marks:
                assert m.xyz.ndim == 2 and m.xyz.shape[1] == 3
                assert len(m.angles) == len(m.xyz) and len(m.owners) == 2
        else:
            with pytest.raises(SwarfError) as e:
                s.jets()
            assert e.value.code == grpc.StatusCode.FAILED_PRECONDITION
    with pytest.raises(SwarfError) as e:
        client.session(s.id)
    assert e.value.code == grpc.StatusCode.NOT_FOUND  # deleted on exit


def zigzag(rows: int, points: int, z: float) -> np.ndarray:
    """A raster of `rows` passes of `points` tips each over [5, 45]^2."""
    out = []
    for r in range(rows):
        x = np.linspace(5, 45, points)
        if r % 2:
            x = x[::-1]
        out.append(np.column_stack([x, np.full(points, 5 + 40 * r / (rows - 1)),
                                    np.full(points, z)]))
    return np.concatenate(out)


def test_resume_after_the_server_is_killed_and_restarted(tmp_path):
    server = Swarfd(tmp_path / "data")
    server.start()
    try:
        path = zigzag(40, 500, -1.0)
        half = len(path) // 2
        c = swarf_client.Client(server.target)
        s = c.create_session((0, 0, 50, 50, 0), spacing=0.25,
                             tools={1: 1.5}, session_id="resume")
        first = s.send(path[:half], batch_points=1000)
        assert first.batches == 10 and first.last_seq == 10
        server.kill()
        # Back a second later, on the same port and data: the next send
        # finds its stream dead, waits for the server and resumes.
        restarter = threading.Timer(1.0, server.start)
        restarter.start()
        second = s.send(path[half:], batch_points=1000)
        restarter.join()
        assert second.resumed >= 1
        assert second.last_seq == 20
        assert second.moves_applied == len(path) - 1
        s.refresh()
        assert s.last_seq == 20 and s.moves_applied == len(path) - 1
        # The same path in one go, on a fresh session: the same heights.
        with c.create_session((0, 0, 50, 50, 0), spacing=0.25,
                              tools={1: 1.5}, delete_on_exit=True) as ref:
            ref.send(path, batch_points=7000)
            np.testing.assert_array_equal(bits(s.heights().z),
                                          bits(ref.heights().z))
        # Kill it again while idle: a new Session object picks up at 21.
        server.kill()
        server.start()
        again = c.session("resume")
        assert again.last_seq == 20
        r = again.send(path[-3:])
        assert r.last_seq == 21 and r.resumed == 0
        c.close()
    finally:
        server.stop()


def test_every_cutter_shape_round_trips(client):
    cutters = {1: swarf_client.Ball(1.5), 2: swarf_client.Flat(0.5),
               3: swarf_client.BullNose(1.0, 0.25),
               4: swarf_client.Cone(1.5, 45.0, 0.1),
               5: swarf_client.Cone(1.0, 15.0),
               6: swarf_client.TaperedBall(2.0, 0.5, 5.0), 7: 0.75}
    with client.create_session((0, 0, 10, 10, 0), spacing=0.25,
                               tools=cutters, delete_on_exit=True) as s:
        want = {k: swarf_client.Ball(c) if isinstance(c, float) else c
                for k, c in cutters.items()}
        assert s.cutters == want
        assert s.tools == {k: c.radius for k, c in want.items()}
        again = client.session(s.id)
        assert again.cutters == want
        for k in cutters:
            r = s.send(np.array([[1, 1 + k, 1], [1, 1 + k, -0.3],
                                 [9, 1 + k, -0.3]]), tool=k, reposition=True)
            assert r.node_lowerings > 0
    # Bad dimensions: INVALID_ARGUMENT naming the field.
    for tools, field in [
            ({1: swarf_client.Cone(1.0, 90.0)}, "tools[0].cone.half_angle_deg"),
            ({1: 1.0, 2: swarf_client.BullNose(1.0, 2.0)},
             "tools[1].bull_nose.corner_radius"),
            ({1: swarf_client.TaperedBall(1.0, 0.0, 5.0)},
             "tools[0].tapered_ball.tip_radius"),
            ({1: swarf_client.Flat(float("nan"))}, "tools[0].flat.radius")]:
        with pytest.raises(SwarfError) as e:
            client.create_session((0, 0, 10, 10, 0), spacing=1, tools=tools)
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert field in e.value.message


def test_error_paths(client):
    with pytest.raises(SwarfError) as e:
        client.create_session((0, 0, -5, 10, 0), spacing=1)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert "stock" in e.value.message
    with pytest.raises(SwarfError) as e:
        client.create_session((0, 0, 10, 10, 0), spacing=1, tools={1: -1})
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert "tools[0].ball.radius" in e.value.message
    with pytest.raises(SwarfError) as e:
        client.session("nope")
    assert e.value.code == grpc.StatusCode.NOT_FOUND

    with client.create_session((0, 0, 10, 10, 0), spacing=0.5,
                               tools={1: 1.0, 2: 0.5}, session_id="errors",
                               delete_on_exit=True) as s:
        with pytest.raises(SwarfError) as e:
            client.create_session((0, 0, 10, 10, 0), spacing=1,
                                  session_id="errors")
        assert e.value.code == grpc.StatusCode.ALREADY_EXISTS
        line = [[1, 5, -0.2], [9, 5, -0.2]]
        bad = np.array(line)
        bad[1, 2] = np.nan
        with pytest.raises(SwarfError) as e:
            s.send(bad)
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "moves.xyz[5]" in e.value.message
        assert e.value.kind == "moves" and e.value.request_id == 1
        with pytest.raises(SwarfError) as e:
            s.send(line, tool=99)
        assert "moves.tool_id" in e.value.message
        # Nothing was consumed: seq 1 is still free.
        assert s.send(line).last_seq == 1
        # A second writer on the same session sending seq 2 (and 3) with
        # other moves: ALREADY_EXISTS, not a silent duplicate, and nothing
        # of it applied.
        other = client.session("errors")
        s.send(line)
        with pytest.raises(SwarfError) as e:
            other.send([[2, 2, -0.1], [8, 8, -0.1], [5, 5, -0.1]],
                       batch_points=2)
        assert e.value.code == grpc.StatusCode.ALREADY_EXISTS
        assert "moves.seq 2" in e.value.message
        assert other.refresh().last_seq == 2
        # It resynchronised: its next send is seq 3.
        assert other.send([[2, 2, -0.1]]).last_seq == 3
        with pytest.raises(SwarfError) as e:
            s.send(np.zeros((0, 3)))
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        with pytest.raises(SwarfError) as e:
            s.send(np.zeros((4, 2)))
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        # A map of 16 Mi cells cannot fit the server's 64 MiB messages.
        with pytest.raises(SwarfError) as e:
            s.error_stats(map=(4096, 4096))
        assert e.value.code == grpc.StatusCode.RESOURCE_EXHAUSTED
        with pytest.raises(SwarfError) as e:
            s.error_stats(samples_per_edge=65)
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        with pytest.raises(SwarfError) as e:
            s.probe([[np.inf, 1]])
        assert "xy[0]" in e.value.message
        # Still serving.
        assert s.refresh().last_seq == 3


def test_messages_past_the_4_mib_default(client):
    with client.create_session((0, 0, 100, 100, 0), spacing=0.1,
                               tools={1: 2.0}, delete_on_exit=True) as s:
        # 200,000 tips: 4.8 MB of doubles, sent in 1 MB batches.
        path = zigzag(200, 1000, -0.5) * [2, 2, 1]
        r = s.send(path)
        assert r.batches == 5 and r.moves_applied == len(path) - 1
        # 1001 x 1001 doubles (8 MB over 256 tiles), and an error map of
        # 9 MB in one message (over gRPC's 4 MiB default).
        h = s.heights()
        assert h.z.shape == (1001, 1001) and h.z.min() < -0.49
        m = s.error_stats(region=(40, 40, 60, 60), samples_per_edge=3,
                          map=(1500, 1500)).map
        assert m is not None and m.shape == (1500, 1500)
        # 200,000 probes: answered in chunks.
        xy = np.column_stack([np.linspace(1, 99, 200_000),
                              np.full(200_000, 50.0)])
        p = s.probe(xy)
        assert p.heights.shape == (200_000,) and p.normals.shape == (200_000, 3)


ROOT = pathlib.Path(__file__).resolve().parents[3]


def run_frontend(program: pathlib.Path, swarfd, cwd: pathlib.Path) -> str:
    """examples/python/frontend.py on `program`: its stdout."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "python" / "frontend.py"),
         str(program), swarfd.target], cwd=cwd, capture_output=True,
        text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_frontend_example_simulates_bear(swarfd, tmp_path):
    """examples/python/frontend.py on bear.nc (the corpus, read in place;
    skipped without it): heights saved, as deep as the program's deepest
    tip."""
    nc = ROOT.parent / "shared" / "corpus" / "bear.nc"
    require_shared(nc)
    out = run_frontend(nc, swarfd, tmp_path)
    # The server's interpreter (the regular expression made 15158 moves of
    # the words before the start was known).
    assert "15155 moves from 15163 lines" in out
    h = np.load(tmp_path / "bear-heights.npy")
    assert h.shape == (801, 801)
    assert h.min() == -17.368 and h.max() <= 0


def test_the_frontend_example_simulates_the_pocket(swarfd, tmp_path):
    """frontend.py on examples/pocket.nc (three flat end mills, tool
    changes): the program's T numbers are the session's tools; the floors
    at the programmed depths, exactly (flat bottoms), the stock top
    elsewhere."""
    out = run_frontend(ROOT / "examples" / "pocket.nc", swarfd, tmp_path)
    assert "18226 moves from" in out, out
    h = np.load(tmp_path / "pocket-heights.npy")
    assert h.shape == (801, 1001)  # [j, i]: y 0..80, x 0..100 at 0.1 mm

    def at(x: float, y: float) -> float:
        return float(h[round(y * 10), round(x * 10)])

    assert h.max() == 0 and h.min() == -6
    for x, y in [(30, 40), (45, 40), (30, 22), (51, 40)]:
        assert at(x, y) == -6, (x, y)     # T1's round pocket
    for x, y in [(76, 40), (61, 40), (90.5, 68.5), (61.5, 11.5)]:
        assert at(x, y) == -4, (x, y)     # T2's rounded rectangle
    for x, y in [(55, 40), (30, 15), (50, 75)]:
        assert at(x, y) == -0.5, (x, y)   # T3's grooves
    for x, y in [(2, 2), (95, 5), (57.5, 40), (60.5, 10.5)]:
        assert at(x, y) == 0, (x, y)      # untouched
    # The round pocket's floor is -6 everywhere within its wall (r 22).
    yy, xx = np.mgrid[0:801, 0:1001] / 10.0
    inside = np.hypot(xx - 30, yy - 40) <= 21.9
    assert (h[inside] == -6).all()


def test_the_frontend_example_simulates_the_vcarve(swarfd, tmp_path):
    """frontend.py on examples/vcarve.nc (a 60-degree V-bit): the frame's
    groove across is the V of the bit at 1 mm deep; the widest leaf as deep
    as its half-width over tan 30."""
    run_frontend(ROOT / "examples" / "vcarve.nc", swarfd, tmp_path)
    h = np.load(tmp_path / "vcarve-heights.npy")
    assert h.shape == (801, 801)
    assert h.max() == 0
    t = np.tan(np.radians(30))
    dx = np.arange(-8, 9) / 10.0               # across x = 5 at y = 40
    want = np.minimum(0, -1 + np.abs(dx) / t)
    np.testing.assert_allclose(h[400, 42:59], want, atol=1e-9)
    # The node (69, 69) on the leaf's middle line near its widest point.
    assert abs(h[690, 690] - (-3.4640)) < 1e-3
    assert h.min() >= -2 / t - 1e-9            # never below the deepest tip


@pytest.mark.parametrize("seq,tool,rapid,reposition,points", [
    (1, 1, False, False, 1), (300, -7, True, False, 5),
    (2**40 + 3, 2**31 - 1, False, True, 40_000), (7, 0, True, True, 2)])
def test_batches_are_serialized_as_protobuf_does(seq, tool, rapid,
                                                 reposition, points):
    from swarf_client import client as impl
    from swarf_client._proto import swarf_pb2 as pb

    xyz = np.random.default_rng(seq).normal(size=(points, 3)) * 1e3
    xyz[0, 0] = -0.0
    want = pb.SimulateRequest(moves=pb.MoveBatch(
        seq=seq, tool_id=tool, xyz=xyz.ravel().tolist(), rapid=rapid,
        reposition=reposition)).SerializeToString()
    got = impl._batch(seq, tool, xyz, rapid, reposition)
    assert got.seq == seq and got.data == want
