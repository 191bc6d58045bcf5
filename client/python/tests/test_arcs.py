"""Arcs through Session.send: chorded by the server as `swarf run` chords
a program's arcs, whatever the batches; the chords are the moves; a bad
arc is INVALID_ARGUMENT naming moves.arcs[k]."""

import math

import grpc
import numpy as np
import pytest

from swarf_client import Arc, SwarfError

STOCK = (-20, -20, 20, 20, 0)
# A half circle, a quarter back, then a helix of two turns (r = 8, z -1.5
# down to -3), between straight feeds.
TIPS = np.array([[-10, 0, 5], [-10, 0, -1], [10, 0, -1], [0, 10, -1],
                 [0, 8, -1.5], [0, 8, -3], [15, 15, -0.5]], float)
ARCS = [Arc(2, (0, 0, 0), clockwise=True), Arc(3, (0, 0, 0)),
        Arc(5, (0, 0, 0), clockwise=True, turns=2)]


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float64).view(np.uint64)


def chords(r: float, sweep: float, tol: float = 0.001) -> int:
    """The chord count of ToolpathBuilder::ArcFeed."""
    return math.ceil(abs(sweep) / (4 * math.asin(math.sqrt(tol / (2 * r)))))


def test_arcs_are_chorded_the_same_across_batches(client):
    with client.create_session(STOCK, nx=160, ny=160, scheme="guarded",
                               tools={1: 1.5}, delete_on_exit=True) as one, \
         client.create_session(STOCK, nx=160, ny=160, scheme="guarded",
                               tools={1: 1.5}, delete_on_exit=True) as split:
        assert one.info().arc_tolerance == 0.001
        r1 = one.send(TIPS, arcs=ARCS)
        # Two points a batch: the boundaries fall on arcs' ends and move.
        r2 = split.send(TIPS, arcs=ARCS, batch_points=2)
        assert r2.batches > 3
        expect = (1 + chords(10, math.pi) + chords(10, math.pi / 2) + 1 +
                  chords(8, 4 * math.pi) + 1)
        assert r1.moves_applied == r2.moves_applied == expect
        a, b = one.heights(owners=True), split.heights(owners=True)
        np.testing.assert_array_equal(bits(a.z), bits(b.z))
        np.testing.assert_array_equal(a.owners, b.owners)
        # The helix ends at its start's xy, 3 mm deep (a node: 0.25 mm grid).
        i, j = 80, 80 + 32
        assert a.z[j, i] == pytest.approx(-3, abs=1e-9)
        assert one.refresh().info().last_position.z == -0.5


def test_coarser_tolerance_gives_fewer_chords(client):
    with client.create_session(STOCK, nx=40, ny=40, tools={1: 1.5},
                               arc_tolerance=0.05,
                               delete_on_exit=True) as s:
        assert s.info().arc_tolerance == 0.05
        r = s.send(TIPS[:3], arcs=ARCS[:1])
        assert r.moves_applied == 1 + chords(10, math.pi, 0.05)


def test_bad_arcs_name_the_field(client):
    with client.create_session(STOCK, nx=40, ny=40, tools={1: 1.5},
                               delete_on_exit=True) as s:
        with pytest.raises(SwarfError) as e:
            s.send(TIPS, arcs=[ARCS[0], Arc(3, (0.5, 0, 0))])
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "moves.arcs[1].centre" in str(e.value)
        assert "radius" in str(e.value)
        with pytest.raises(SwarfError) as e:
            s.send(TIPS, arcs=[Arc(2, (0, 0, 0), turns=0)])
        assert "moves.arcs[0].turns" in str(e.value)
        with pytest.raises(SwarfError) as e:
            s.send(TIPS, arcs=[Arc(0, (0, 0, 0))])  # checked client-side
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert s.refresh().moves_applied == 0
        s.send(TIPS, arcs=ARCS)  # the session goes on
        assert s.refresh().last_seq == 1
    with pytest.raises(SwarfError) as e:
        client.create_session(STOCK, nx=4, ny=4, arc_tolerance=20)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert "arc_tolerance" in str(e.value)
