"""The design over the API from Python: set_design from triangles and from
an STL file (the same figures), deviation() naming the deep pass's move,
bad input as SwarfError with the exact code, and the design surviving a
killed and restarted server."""

import math

import grpc
import numpy as np
import pytest

import swarf_client
from swarf_client import SwarfError

from conftest import Swarfd

R = 2.0          # ball radius (mm)
FLOOR = -1.0
DEEP = 9         # the pass 0.25 mm too deep


def raster() -> np.ndarray:
    """Passes along x at y = 0..20 as one polyline, pass DEEP deeper."""
    pts = []
    for k in range(21):
        z = FLOOR - 0.25 if k == DEEP else FLOOR
        xa, xb = (23.0, -3.0) if k % 2 else (-3.0, 23.0)
        pts += [(xa, k, z), (xb, k, z)]
    return np.array(pts, dtype=np.float64)


def floor_triangles() -> np.ndarray:
    """The floor z = FLOOR over [-5, 25]^2, two triangles."""
    a, b, c, d = (-5, -5, FLOOR), (25, -5, FLOOR), (25, 25, FLOOR), (-5, 25, FLOOR)
    return np.array([[a, b, c], [a, c, d]], dtype=np.float64)


def cut(client, session_id):
    s = client.create_session((0, 0, 20, 20, 0), spacing=0.1, tools={1: R},
                              session_id=session_id)
    s.send(raster())
    return s


def test_deviation_names_the_deep_pass(client, tmp_path):
    s = cut(client, "design-py")
    try:
        with pytest.raises(SwarfError) as e:
            s.deviation()
        assert e.value.code == grpc.StatusCode.FAILED_PRECONDITION
        info = s.set_design(floor_triangles())
        assert info.triangles == 2 and info.covered_nodes == 201 * 201
        d = s.deviation(tolerance=0.05, allowance=0.07)
        assert not d.ok
        assert d.gouge_max == pytest.approx(0.25, abs=1e-9)
        # One move a pass and one a link: the deep pass is move 2 * DEEP.
        assert d.gouge_move == 2 * DEEP
        assert [m.move for m in d.gouge_moves] == [2 * DEEP]
        lines = list(range(100, 100 + 2 * 21))
        assert d.lines(lines)[0][0] == 100 + 2 * DEEP
        # The scallops between 1 mm passes of a 2 mm-radius ball.
        assert d.excess_max == pytest.approx(R - math.sqrt(R * R - 0.25),
                                             abs=1e-6)
        # Per node: the heights less the floor, the deep pass 0.25 below.
        m = s.deviation_map()
        h = s.heights(precision="float")
        np.testing.assert_array_equal(m.z, h.z - np.float32(FLOOR))
        assert float(m.z.min()) == pytest.approx(-0.25, abs=1e-6)
        assert m.z.shape == (201, 201)
        # The same floor as an STL file: the same figures.
        stl = tmp_path / "floor.stl"
        tris = floor_triangles().astype(np.float32)
        rec = np.zeros(2, dtype=[("n", "<f4", 3), ("v", "<f4", 9),
                                 ("a", "<u2")])
        rec["v"] = tris.reshape(-1, 9)
        stl.write_bytes(b"floor".ljust(80) + np.uint32(2).tobytes() +
                        rec.tobytes())
        s.set_design(str(stl))
        assert s.deviation(tolerance=0.05, allowance=0.07) == d
        # Bad input: the design stays.
        with pytest.raises(SwarfError) as e:
            s.set_design(b"G0 X0 Y0\n")
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        with pytest.raises(SwarfError) as e:
            s.set_design(floor_triangles() + np.array([500.0, 0, 0]))
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "outside the stock" in str(e.value)
        with pytest.raises(SwarfError) as e:
            s.set_design(np.zeros((2, 3)))
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert s.deviation(tolerance=0.05, allowance=0.07) == d
    finally:
        s.delete()


def test_design_survives_a_killed_server(tmp_path):
    server = Swarfd(tmp_path / "data")
    server.start()
    try:
        c = swarf_client.Client(server.target)
        s = cut(c, "design-kill")
        s.set_design(floor_triangles(), name="floor")
        before = s.deviation(tolerance=0.05)
        server.kill()
        server.start()
        again = c.session("design-kill")
        assert again.deviation(tolerance=0.05) == before
        c.close()
    finally:
        server.stop()
