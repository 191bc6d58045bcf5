"""The swarf client: sessions, move streaming and reads as numpy arrays.

Units: millimetres for lengths and positions, degrees for angles. Positions
of moves are the TOOL TIP (the lowest point of the tool). Grids: a session
has nx x ny ELEMENTS, hence (ny + 1) x (nx + 1) nodes; arrays of node
values are indexed [j, i] (row j along y, column i along x), node (i, j) at
(x0 + i * (x1 - x0) / nx, y0 + j * (y1 - y0) / ny).
"""

from __future__ import annotations

import dataclasses
import math
import os
import queue
import threading
import time
from typing import (Any, Callable, Dict, Iterable, Iterator, List, Mapping,
                    Optional,
                    Sequence, Tuple, Union)

import grpc  # type: ignore[import]  # grpcio ships no type hints
import numpy as np
import numpy.typing as npt

from ._proto import swarf_pb2 as pb
from ._proto import swarf_pb2_grpc as pb_grpc

__all__ = [
    "Client", "Session", "SwarfError", "SendResult", "Heights", "Jets",
    "ErrorStats", "Mark", "ProbeResult", "TILE_SIZE", "Ball", "Flat",
    "BullNose", "Cone", "TaperedBall", "Cutter", "Arc", "ProgramResult",
]

TILE_SIZE = 64  # nodes per tile side (Session.tile_size)

# Every message stays well under gRPC's 4 MiB default: a batch of 40,000
# points is 960 kB, a probe chunk of 40,000 points answers in about 1.7 MB.
DEFAULT_BATCH_POINTS = 40_000
PROBE_CHUNK_POINTS = 40_000
# Codes after which a stream is resumed (the server went away or restarts).
_RESUMABLE = (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED,
              grpc.StatusCode.UNKNOWN, grpc.StatusCode.INTERNAL,
              grpc.StatusCode.ABORTED)

_SCHEMES = {"taylor": pb.SCHEME_TAYLOR, "zmap": pb.SCHEME_ZMAP,
            "guarded": pb.SCHEME_GUARDED, "exact": pb.SCHEME_EXACT}
_SCHEME_NAMES = {v: k for k, v in _SCHEMES.items()}
_CODES = {c.value[0]: c for c in grpc.StatusCode}

FloatArray = npt.NDArray[np.float64]
ArrayLike = npt.ArrayLike


# ------------------------------------------------------------------ cutters
# The proto's Tool shapes, in its terms: radii (mm) and HALF angles (degrees,
# the flank against the axis: a 90 degree V-bit has 45). Every cutter is
# positioned by its tip; the server validates the dimensions
# (INVALID_ARGUMENT naming e.g. "tools[1].cone.half_angle_deg").


@dataclasses.dataclass(frozen=True)
class Ball:
    """A ball-end cutter."""
    radius: float


@dataclasses.dataclass(frozen=True)
class Flat:
    """A flat-end cutter: a flat disk bottom and a cylindrical side."""
    radius: float


@dataclasses.dataclass(frozen=True)
class BullNose:
    """A flat annulus of radius - corner_radius and a torus corner."""
    radius: float
    corner_radius: float


@dataclasses.dataclass(frozen=True)
class Cone:
    """A V-bit, chamfer mill or engraver: a flat tip of tip_radius (0:
    sharp), a flank at half_angle_deg from the axis up to radius."""
    radius: float
    half_angle_deg: float
    tip_radius: float = 0.0


@dataclasses.dataclass(frozen=True)
class TaperedBall:
    """A ball tip of tip_radius tangent to a flank at half_angle_deg from
    the axis, up to radius."""
    radius: float
    tip_radius: float
    half_angle_deg: float


Cutter = Union[Ball, Flat, BullNose, Cone, TaperedBall]


def _tool_proto(tool_id: int, cutter: Union[float, Cutter]) -> Any:
    """The proto Tool for a cutter (a bare number: a ball's radius)."""
    t = pb.Tool(id=int(tool_id))
    if isinstance(cutter, Ball):
        t.ball.radius = float(cutter.radius)
    elif isinstance(cutter, Flat):
        t.flat.radius = float(cutter.radius)
    elif isinstance(cutter, BullNose):
        t.bull_nose.radius = float(cutter.radius)
        t.bull_nose.corner_radius = float(cutter.corner_radius)
    elif isinstance(cutter, Cone):
        t.cone.radius = float(cutter.radius)
        t.cone.half_angle_deg = float(cutter.half_angle_deg)
        t.cone.tip_radius = float(cutter.tip_radius)
    elif isinstance(cutter, TaperedBall):
        t.tapered_ball.radius = float(cutter.radius)
        t.tapered_ball.tip_radius = float(cutter.tip_radius)
        t.tapered_ball.half_angle_deg = float(cutter.half_angle_deg)
    else:
        t.ball.radius = float(cutter)
    return t


def _cutter_of(t: Any) -> Optional[Cutter]:
    """The cutter of a proto Tool (None without a shape)."""
    shape = t.WhichOneof("shape")
    if shape == "ball":
        return Ball(t.ball.radius)
    if shape == "flat":
        return Flat(t.flat.radius)
    if shape == "bull_nose":
        return BullNose(t.bull_nose.radius, t.bull_nose.corner_radius)
    if shape == "cone":
        return Cone(t.cone.radius, t.cone.half_angle_deg, t.cone.tip_radius)
    if shape == "tapered_ball":
        return TaperedBall(t.tapered_ball.radius, t.tapered_ball.tip_radius,
                           t.tapered_ball.half_angle_deg)
    return None


class SwarfError(Exception):
    """A call or request the server refused.

    Attributes:
      code: the grpc.StatusCode (INVALID_ARGUMENT for bad input, naming the
        field in the message; NOT_FOUND, ALREADY_EXISTS, RESOURCE_EXHAUSTED,
        FAILED_PRECONDITION, UNAVAILABLE, UNAUTHENTICATED, ...).
      message: the server's message.
      request_id: for an error on the Simulate stream, the batch's seq or
        the request's id (see `kind`); None for a whole call.
      kind: "moves", "tiles", "stats", "marks", "subscribe" or None.
    """

    def __init__(self, code: grpc.StatusCode, message: str,
                 request_id: Optional[int] = None,
                 kind: Optional[str] = None) -> None:
        super().__init__(f"{code.name}: {message}")
        self.code = code
        self.message = message
        self.request_id = request_id
        self.kind = kind


def _from_rpc(e: grpc.RpcError) -> SwarfError:
    code = e.code() if callable(getattr(e, "code", None)) else None
    details = e.details() if callable(getattr(e, "details", None)) else str(e)
    return SwarfError(code or grpc.StatusCode.UNKNOWN, details or "")


def _from_request_error(e: Any) -> SwarfError:
    kind = pb.RequestKind.Name(e.kind).replace("REQUEST_KIND_", "").lower()
    return SwarfError(_CODES.get(e.code, grpc.StatusCode.UNKNOWN), e.message,
                      e.request_id, None if kind == "unspecified" else kind)


_PLANES = {"xy": pb.ARC_PLANE_XY, "xz": pb.ARC_PLANE_XZ,
           "yz": pb.ARC_PLANE_YZ}


@dataclasses.dataclass(frozen=True)
class Arc:
    """An arc of Session.send: the move ending at tips[end] turns about
    `centre` instead of going straight (G2/G3 with their centre).

    end: index of the tip the arc ends at (>= 1: it starts at tips[end - 1]).
    centre: (x, y, z) mm; the coordinate along the plane's axis is unused.
    clockwise: G2 (seen from the axis' positive side); False: G3.
    plane: "xy" (G17, about z), "xz" (G18, about y) or "yz" (G19, about x).
    turns: turns begun (G2/G3's P), >= 1; a helix when the axis coordinate
      of the end differs from the start's.
    The server chords it within the session's arc_tolerance exactly as
    `swarf run` chords a program's arcs; the chords are the moves counted.
    """
    end: int
    centre: Tuple[float, float, float]
    clockwise: bool = False
    plane: str = "xy"
    turns: int = 1

    def _proto(self, end_index: int) -> Any:
        if self.plane not in _PLANES:
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             f"arc plane must be one of {sorted(_PLANES)}, "
                             f"got {self.plane!r}")
        x, y, z = (float(v) for v in self.centre)
        return pb.Arc(end_index=end_index, centre=pb.Point3(x=x, y=y, z=z),
                      plane=_PLANES[self.plane], clockwise=self.clockwise,
                      turns=int(self.turns))


# Program uploads go in chunks of this many bytes (under gRPC's 4 MiB).
PROGRAM_CHUNK_BYTES = 1 << 20
_DIALECTS = {"linuxcnc": pb.DIALECT_LINUXCNC, "fanuc": pb.DIALECT_FANUC,
             "grbl": pb.DIALECT_GRBL}


@dataclasses.dataclass(frozen=True)
class ProgramResult:
    """What Session.run_program did (the server's ProgramDone)."""
    first_seq: int       # seq of the program's first batch
    last_seq: int        # and of its last
    moves: int           # moves of the program (arcs as their chords)
    points: int
    source_lines: int
    blocks_executed: int
    # What `swarf run` prints before simulating, naming file and line:
    # notes, ignored words, dropped moves, a cut leaving the stock.
    warnings: List[str]
    moves_applied: int   # in the session, in total, after the program
    node_lowerings: int  # by the batches applied by this call
    resumed: int         # times the program was resumed after a drop


@dataclasses.dataclass(frozen=True)
class SendResult:
    """What Session.send did: its last batch's acknowledgement."""
    last_seq: int        # seq of the last batch sent
    batches: int         # batches sent by this call
    moves_applied: int   # moves in the session, in total
    node_lowerings: int   # node updates by this call's batches
    version: int         # grid version after the last batch
    resumed: int         # times the stream was resumed during the call


@dataclasses.dataclass(frozen=True)
class Heights:
    """Node heights (mm) z[j, i] at x[i], y[j] (mm); owners[j, i] is the id
    of the move that set each node (-1: the stock top) when asked for."""
    x: FloatArray
    y: FloatArray
    z: npt.NDArray[Any]
    owners: Optional[npt.NDArray[np.int32]] = None


@dataclasses.dataclass(frozen=True)
class Jets:
    """Heights w (mm) and their derivatives wx, wy (dimensionless), wxx,
    wxy, wyy (1/mm) per node, [j, i], at x[i], y[j] (taylor sessions)."""
    x: FloatArray
    y: FloatArray
    w: FloatArray
    wx: npt.NDArray[np.float32]
    wy: npt.NDArray[np.float32]
    wxx: npt.NDArray[np.float32]
    wxy: npt.NDArray[np.float32]
    wyy: npt.NDArray[np.float32]


@dataclasses.dataclass(frozen=True)
class ErrorStats:
    """The scheme's error against the exact machined surface (mm); map[r, c]
    is the max error per cell over the region (0 where no sample fell),
    cell (0, 0) at the region's (x0, y0)."""
    scheme: str
    max_error: float
    mean_error: float
    rms_error: float
    max_at: Tuple[float, float]
    samples: int
    map: Optional[npt.NDArray[np.float32]] = None


@dataclasses.dataclass(frozen=True)
class Mark:
    """A cutting mark: vertices xyz (K, 3) mm on the simulated surface, the
    two surfaces' move ids (-1: the stock top) and per-vertex angles (deg)
    between their normals."""
    xyz: FloatArray
    owners: Tuple[int, ...]
    angles: FloatArray
    closed: bool


@dataclasses.dataclass(frozen=True)
class ProbeResult:
    """Per point: the reconstructed height (mm), the outward unit normal
    (N, 3) and the id of the move owning the nearest node."""
    heights: FloatArray
    normals: FloatArray
    owners: npt.NDArray[np.int64]


@dataclasses.dataclass(frozen=True)
class DesignInfo:
    """The design a session holds: its triangle count, the grid nodes it
    lies over and its bounds (mm)."""
    name: str
    triangles: int
    covered_nodes: int
    min: Tuple[float, float, float]
    max: Tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class DeviationMove:
    """A move's share of the deviation: its worst gouge (or excess) out of
    tolerance (mm, positive), where, and the area it cut out of tolerance."""
    move: int
    depth: float
    x: float
    y: float
    area_mm2: float


@dataclasses.dataclass(frozen=True)
class Deviation:
    """The machined surface against the design's top envelope (mm; depths
    positive). gouge_moves / excess_moves are move ids (0-based, in the
    order the session applied them), deepest first; lines() maps them to
    program lines. The verdict (ok) uses the normal deviation."""
    triangles: int
    nodes: int
    samples: int
    gouge_max: float
    gouge_at: Tuple[float, float]
    gouge_move: int
    gouge_volume_mm3: float
    excess_max: float
    excess_at: Tuple[float, float]
    excess_mean: float
    excess_volume_mm3: float
    normal_gouge_max: float
    normal_excess_max: float
    allowance: float
    tolerance: float
    out_of_tolerance_area_mm2: float
    ok: bool
    gouge_moves: List[DeviationMove]
    excess_moves: List[DeviationMove]

    def lines(self, move_lines: Sequence[int]) -> List[Tuple[int, DeviationMove]]:
        """The gouging moves as (program line, move), given each move's line
        (move_lines[id])."""
        return [(int(move_lines[m.move]), m) for m in self.gouge_moves
                if 0 <= m.move < len(move_lines)]


# Bytes per SetDesign chunk: well within gRPC's default 4 MiB.
DESIGN_CHUNK_BYTES = 1 << 20


def _read(path_or_bytes: Union[None, str, bytes]) -> Optional[bytes]:
    if path_or_bytes is None or isinstance(path_or_bytes, bytes):
        return path_or_bytes
    with open(path_or_bytes, "rb") as f:
        return f.read()


def _rect(region: Optional[Sequence[float]]) -> Optional[Any]:
    if region is None:
        return None
    x0, y0, x1, y1 = (float(v) for v in region)
    return pb.Rect(x0=x0, y0=y0, x1=x1, y1=y1)


class Client:
    """A connection to swarfd.

    Args:
      target: "host:port" of swarfd.
      token: bearer token (swarfd --auth_tokens_file), or None.
      tls: serve over TLS; root_certificates (PEM bytes or a path) verifies
        the server (system roots when None); certificate_chain and
        private_key present a client certificate.
      timeout: seconds for each unary call.
      wait_for_ready: a call made while the server cannot be reached (not
        started yet, restarting, a connection attempt that timed out) waits
        for it up to `timeout` instead of failing at once with UNAVAILABLE.

    Messages from the server may be as large as its --max_message_mb: the
    channel accepts any size, and what the client sends (batches, probes)
    is split to stay under gRPC's usual 4 MiB. Thread-safe; use one Session
    object per thread.
    """

    def __init__(self, target: str = "127.0.0.1:50051", *,
                 token: Optional[str] = None, tls: bool = False,
                 root_certificates: Union[None, str, bytes] = None,
                 certificate_chain: Union[None, str, bytes] = None,
                 private_key: Union[None, str, bytes] = None,
                 timeout: float = 60.0, wait_for_ready: bool = True) -> None:
        options = [("grpc.max_receive_message_length", -1),
                   ("grpc.max_send_message_length", -1),
                   # A restarted server is found again within 2 s, not
                   # after gRPC's default backoff of up to 2 minutes.
                   ("grpc.initial_reconnect_backoff_ms", 100),
                   ("grpc.min_reconnect_backoff_ms", 100),
                   ("grpc.max_reconnect_backoff_ms", 2000)]
        if tls:
            creds = grpc.ssl_channel_credentials(
                _read(root_certificates), _read(private_key),
                _read(certificate_chain))
            self._channel = grpc.secure_channel(target, creds, options)
        else:
            self._channel = grpc.insecure_channel(target, options)
        self._stub = pb_grpc.SwarfStub(self._channel)
        self._token = token
        self.timeout = timeout
        self.wait_for_ready = wait_for_ready
        self.target = target

    # -- plumbing

    def _md(self, session_id: str = "") -> List[Tuple[str, str]]:
        md = []
        if session_id:
            md.append(("x-swarf-session", session_id))
        if self._token:
            md.append(("authorization", f"Bearer {self._token}"))
        return md

    def _call(self, method: str, request: Any, session_id: str = "") -> Any:
        try:
            return getattr(self._stub, method)(
                request, metadata=self._md(session_id), timeout=self.timeout,
                wait_for_ready=self.wait_for_ready)
        except grpc.RpcError as e:
            raise _from_rpc(e) from None

    def _stream(self, method: str, request: Any,
                session_id: str) -> Iterator[Any]:
        try:
            yield from getattr(self._stub, method)(
                request, metadata=self._md(session_id), timeout=self.timeout,
                wait_for_ready=self.wait_for_ready)
        except grpc.RpcError as e:
            raise _from_rpc(e) from None

    # -- API

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def health(self, timeout: float = 5.0) -> bool:
        """Whether the server answers within `timeout` seconds (waiting for
        it to come up; a ListSessions call, so the token is checked too)."""
        try:
            self._stub.ListSessions(pb.ListSessionsRequest(),
                                    metadata=self._md(), timeout=timeout,
                                    wait_for_ready=True)
            return True
        except grpc.RpcError:
            return False

    def create_session(self, stock: Sequence[float], *,
                       spacing: Optional[float] = None,
                       nx: Optional[int] = None, ny: Optional[int] = None,
                       scheme: str = "taylor",
                       tools: Union[Mapping[int, Union[float, Cutter]],
                                    float, Cutter] = 1.0,
                       session_id: str = "",
                       arc_tolerance: Optional[float] = None,
                       delete_on_exit: bool = False) -> "Session":
        """Creates a session.

        Args:
          stock: (x0, y0, x1, y1, z_top) mm: the stock rectangle, flat top.
          spacing: target node spacing (mm); or nx and ny, the ELEMENT
            counts along x and y (nodes: nx + 1, ny + 1).
          scheme: "taylor" (heights and derivatives, the paper's eq. 1-2),
            "zmap", "guarded" (the server's default) or "exact".
          tools: {tool id: cutter}, or one cutter (tool id 1); a cutter is
            Ball, Flat, BullNose, Cone or TaperedBall, or a number: a
            ball-end radius (mm).
          session_id: 1-64 of [A-Za-z0-9_-]; generated when empty.
          arc_tolerance: chord tolerance of arcs (mm, [1e-6, 10]; default
            0.001, as `swarf run`).
          delete_on_exit: the session's `with` block deletes it.
        Raises SwarfError (INVALID_ARGUMENT naming the field,
        ALREADY_EXISTS, RESOURCE_EXHAUSTED).
        """
        if scheme not in _SCHEMES:
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             f"scheme must be one of {sorted(_SCHEMES)}, got {scheme!r}")
        x0, y0, x1, y1, z_top = (float(v) for v in stock)
        req = pb.CreateSessionRequest(
            session_id=session_id,
            stock=pb.Stock(x0=x0, y0=y0, x1=x1, y1=y1, z_top=z_top),
            scheme=_SCHEMES[scheme])
        if spacing is not None:
            req.spacing = float(spacing)
        if nx is not None or ny is not None:
            req.nx, req.ny = int(nx or 0), int(ny or 0)
        if arc_tolerance is not None:
            req.arc_tolerance.value = float(arc_tolerance)
        if not isinstance(tools, Mapping):
            tools = {1: tools}
        for tool_id, cutter in tools.items():
            req.tools.append(_tool_proto(tool_id, cutter))
        info = self._call("CreateSession", req, session_id)
        return Session(self, info, delete_on_exit=delete_on_exit)

    def session(self, session_id: str, *,
                delete_on_exit: bool = False) -> "Session":
        """An existing session (NOT_FOUND if absent or another token's)."""
        info = self._call("GetSession", pb.GetSessionRequest(
            session_id=session_id), session_id)
        return Session(self, info, delete_on_exit=delete_on_exit)

    def sessions(self) -> List[str]:
        """Ids of this token's sessions."""
        resp = self._call("ListSessions", pb.ListSessionsRequest())
        return [s.session_id for s in resp.sessions]


def _varint(v: int) -> bytes:
    v &= (1 << 64) - 1  # negative int32/int64: ten bytes, two's complement
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


@dataclasses.dataclass(frozen=True)
class _Batch:
    seq: int
    data: bytes  # a serialized SimulateRequest{moves}


def _batch(seq: int, tool_id: int, xyz: FloatArray, rapid: bool,
           reposition: bool, arcs: Sequence[bytes] = ()) -> _Batch:
    """A SimulateRequest of one MoveBatch, serialized straight from the
    array (the same bytes protobuf writes; about 10x faster for large
    batches, and no Python objects per point). `arcs`: serialized Arcs."""
    points = np.ascontiguousarray(xyz, dtype="<f8").tobytes()
    body = b"".join([
        b"\x08", _varint(seq),                          # seq = 1
        b"\x10" + _varint(tool_id) if tool_id else b"",  # tool_id = 2
        b"\x1a", _varint(len(points)), points,           # xyz = 3, packed
        b"\x20\x01" if rapid else b"",                   # rapid = 4
        b"\x28\x01" if reposition else b"",              # reposition = 5
    ] + [b"\x3a" + _varint(len(a)) + a for a in arcs])  # arcs = 7
    return _Batch(seq, b"\x0a" + _varint(len(body)) + body)  # moves = 1


class _Stream:
    """One Simulate stream: requests (serialized) go through a queue that
    gRPC's sending thread drains, responses are read by the caller."""

    def __init__(self, client: Client, session_id: str) -> None:
        self._queue: "queue.Queue[Any]" = queue.Queue()
        simulate = client._channel.stream_stream(
            "/swarf.v1.Swarf/Simulate", request_serializer=None,
            response_deserializer=pb.SimulateResponse.FromString)
        self._call = simulate(self._requests(),
                              metadata=client._md(session_id))

    def _requests(self) -> Iterator[Any]:
        while True:
            req = self._queue.get()
            if req is None:
                return
            yield req

    def send(self, req: bytes) -> None:
        self._queue.put(req)

    def recv(self) -> Any:
        return next(self._call)  # grpc.RpcError when the stream fails

    def close(self) -> None:
        self._queue.put(None)
        self._call.cancel()


class Session:
    """A workpiece session. Not thread-safe (one stream, one seq counter).

    Use as a context manager: with delete_on_exit=True (at create_session,
    or set the attribute) the session is deleted when the block ends.
    """

    def __init__(self, client: Client, info: Any,
                 delete_on_exit: bool = False) -> None:
        self._client = client
        self._info = info
        self.delete_on_exit = delete_on_exit
        self._stream: Optional[_Stream] = None
        self._next_seq = info.last_seq + 1
        self.resume_timeout = 60.0  # seconds send() waits for a server back
        self.window = 8  # batches in flight before send() waits for acks

    # -- description

    @property
    def id(self) -> str:
        return str(self._info.session_id)

    @property
    def stock(self) -> Tuple[float, float, float, float, float]:
        s = self._info.stock
        return (s.x0, s.y0, s.x1, s.y1, s.z_top)

    @property
    def nx(self) -> int:
        """ELEMENTS along x (nx + 1 node columns)."""
        return int(self._info.nx)

    @property
    def ny(self) -> int:
        """Elements along y (ny + 1 node rows)."""
        return int(self._info.ny)

    @property
    def scheme(self) -> str:
        return _SCHEME_NAMES.get(self._info.scheme, "guarded")

    @property
    def tools(self) -> Dict[int, float]:
        """{tool id: the cutter's (outer) radius (mm)}."""
        return {t.id: c.radius for t in self._info.tools
                if (c := _cutter_of(t)) is not None}

    @property
    def cutters(self) -> Dict[int, Cutter]:
        """{tool id: its cutter (Ball, Flat, BullNose, Cone, TaperedBall)}."""
        return {t.id: c for t in self._info.tools
                if (c := _cutter_of(t)) is not None}

    @property
    def last_seq(self) -> int:
        """The seq of the last batch the server applied (as last read)."""
        return int(self._info.last_seq)

    @property
    def moves_applied(self) -> int:
        return int(self._info.moves_applied)

    def node_x(self) -> FloatArray:
        """x (mm) of every node column, i = 0..nx."""
        x0, _, x1, _, _ = self.stock
        return x0 + np.arange(self.nx + 1) * ((x1 - x0) / self.nx)

    def node_y(self) -> FloatArray:
        """y (mm) of every node row, j = 0..ny."""
        _, y0, _, y1, _ = self.stock
        return y0 + np.arange(self.ny + 1) * ((y1 - y0) / self.ny)

    def refresh(self) -> "Session":
        """Re-reads the session's state from the server."""
        self._info = self._client._call(
            "GetSession", pb.GetSessionRequest(session_id=self.id), self.id)
        return self

    def info(self) -> Any:
        """The last swarf.v1.Session read (protobuf message)."""
        return self._info

    # -- moves

    def send(self, tips: ArrayLike, *, tool: Optional[int] = None,
             reposition: bool = False, rapid: bool = False,
             arcs: Sequence[Arc] = (),
             batch_points: int = DEFAULT_BATCH_POINTS) -> SendResult:
        """Simulates a polyline of tool-tip positions.

        Args:
          tips: (N, 3) array of tip positions (mm). The first continues from
            the session's last position (in a session's first call it only
            places the tool); each next point is one straight move.
          tool: the tool id (default: the session's first tool).
          reposition: the first point only places the tool (no move to it).
          rapid: the moves are rapids (G0); simulated alike.
          arcs: Arc(end, centre, ...) per move that is an arc (end >= 1,
            ascending): the server chords them, and the chords count as
            moves (moves_applied, owners). Batches never start with an arc.
          batch_points: points per MoveBatch (the server's limit is
            --max_batch_points; the default keeps messages under 1 MB).
        Returns when every batch is acknowledged (applied, and durable on a
        journaled server). Batches carry consecutive seqs; if the stream
        drops or the server restarts, the call resumes from the server's
        last_seq for up to `resume_timeout` seconds.
        Raises SwarfError (INVALID_ARGUMENT naming the field, e.g.
        moves.xyz[k] or moves.tool_id; ALREADY_EXISTS if another writer
        took a seq; NOT_FOUND; UNAVAILABLE when the server stays away).
        """
        xyz = np.ascontiguousarray(tips, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             f"tips must have shape (N, 3), got {xyz.shape}")
        if len(xyz) == 0:
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             "tips is empty: at least one point is needed")
        if batch_points < 1:
            raise ValueError("batch_points must be at least 1")
        tool_id = tool if tool is not None else self._info.tools[0].id
        by_end = {}
        for a in arcs:
            if not 1 <= a.end < len(xyz) or a.end in by_end:
                raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                                 f"arc end {a.end} must be a tip index in "
                                 f"[1, {len(xyz) - 1}], one arc per tip")
            by_end[a.end] = a
        # Batch boundaries, moved back off a tip an arc ends at (an arc
        # starts at its batch's previous point).
        starts = [0]
        while starts[-1] + batch_points < len(xyz):
            b = starts[-1] + batch_points
            while b in by_end and b > starts[-1] + 1:
                b -= 1
            while b in by_end:
                b += 1
            if b >= len(xyz):
                break
            starts.append(b)
        ends = starts[1:] + [len(xyz)]
        batches = [
            _batch(self._next_seq + k, tool_id, xyz[lo:hi], rapid,
                   reposition and lo == 0,
                   [by_end[i]._proto(i - lo).SerializeToString()
                    for i in sorted(by_end) if lo <= i < hi])
            for k, (lo, hi) in enumerate(zip(starts, ends))]
        return self._send_batches(batches)

    def run_program(self, program: Union[str, bytes, "os.PathLike[str]"], *,
                    tools: Optional[Mapping[int, int]] = None,
                    dialect: str = "linuxcnc", name: Optional[str] = None,
                    arc_tolerance: Optional[float] = None,
                    start: Optional[Sequence[float]] = None,
                    home: Optional[Sequence[float]] = None,
                    tool_change_position: Optional[Sequence[float]] = None,
                    m6_forgets_position: bool = False, max_blocks: int = 0,
                    strict: bool = False, batch_points: int = 0,
                    progress: Optional[Callable[[Any], None]] = None
                    ) -> ProgramResult:
        """Has the server interpret a G-code program and simulate it, as
        `swarf run` does (the same interpreter, options and batches: the
        same heights bit for bit).

        Args:
          program: a path to a G-code file, its text (str with a newline,
            or bytes). Uploaded in chunks of PROGRAM_CHUNK_BYTES.
          tools: {T number: session tool id}; a T number not listed is the
            session tool of that id, or the session's only tool.
          dialect: "linuxcnc" (default), "fanuc" or "grbl".
          name: the file name in messages (default: the path's name, or
            "program").
          arc_tolerance: chord tolerance of its arcs (mm; default: the
            session's).
          start, home, tool_change_position: (x, y, z) machine mm, as
            `swarf run --start/--home/--tool-change-position`.
          m6_forgets_position, max_blocks, strict: as `swarf run`.
          batch_points: points per batch (0: 20000, `swarf run`'s).
          progress: called with each batch's Ack (seq, moves_applied,
            node_lowerings, ...) as it is applied.
        Durable as send(): if the stream drops or the server restarts, it
        waits for it (`resume_timeout`) and resumes the program the server
        journaled (batches it has are acknowledged, not applied again).
        Raises SwarfError: INVALID_ARGUMENT "FILE: line N: ..." for an
        error in the program (nothing applied), or naming a bad option.
        """
        if isinstance(program, bytes):
            data, label = program, "program"
        elif isinstance(program, str) and "\n" in program:
            data, label = program.encode(), "program"
        else:
            path = os.fspath(program)
            with open(path, "rb") as f:
                data = f.read()
            label = os.path.basename(path)
        if dialect not in _DIALECTS:
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             f"dialect must be one of {sorted(_DIALECTS)}, "
                             f"got {dialect!r}")
        opt = pb.ProgramOptions(
            name=name or label, dialect=_DIALECTS[dialect],
            m6_forgets_position=m6_forgets_position, max_blocks=max_blocks,
            strict=strict, first_seq=self._next_seq, batch_points=batch_points)
        for t, tool_id in (tools or {}).items():
            opt.tools[int(t)] = int(tool_id)
        if arc_tolerance is not None:
            opt.arc_tolerance.value = float(arc_tolerance)
        for field, p in (("start", start), ("home", home),
                         ("tool_change_position", tool_change_position)):
            if p is not None:
                x, y, z = (float(v) for v in p)
                getattr(opt, field).CopyFrom(pb.Point3(x=x, y=y, z=z))
        upload = []
        for off in range(0, max(len(data), 1), PROGRAM_CHUNK_BYTES):
            last = off + PROGRAM_CHUNK_BYTES >= len(data)
            chunk = pb.ProgramChunk(request_id=1, offset=off,
                                    data=data[off:off + PROGRAM_CHUNK_BYTES],
                                    last=last)
            if last:
                chunk.options.CopyFrom(opt)
            upload.append(pb.SimulateRequest(program=chunk).SerializeToString())
        resume = [pb.SimulateRequest(program=pb.ProgramChunk(
            request_id=1, resume=True, last=True,
            options=pb.ProgramOptions(first_seq=opt.first_seq))
        ).SerializeToString()]
        requests = upload
        lowered = 0
        resumed = 0
        deadline: Optional[float] = None
        while True:
            try:
                stream = self._open()
                for r in requests:
                    stream.send(r)
                while True:
                    resp = stream.recv()
                    if resp.HasField("ack"):
                        if not resp.ack.duplicate:
                            lowered += resp.ack.node_lowerings
                        if progress is not None:
                            progress(resp.ack)
                        continue
                    break
            except (grpc.RpcError, StopIteration) as e:
                deadline = self._stream_broke(e, deadline)
                self._wait_for_server(deadline)
                requests = resume
                resumed += 1
                continue
            deadline = None
            if resp.HasField("error"):
                failure = resp.error
                if (requests is resume and failure.code ==
                        grpc.StatusCode.FAILED_PRECONDITION.value[0]):
                    requests = upload  # nothing journaled: upload again
                    continue
                self._drop_stream()
                self._resync()
                raise _from_request_error(failure)
            if resp.HasField("program_done"):
                d = resp.program_done
                self._next_seq = d.last_seq + 1
                self.refresh()
                return ProgramResult(
                    first_seq=d.first_seq, last_seq=d.last_seq, moves=d.moves,
                    points=d.points, source_lines=d.source_lines,
                    blocks_executed=d.blocks_executed,
                    warnings=list(d.warnings),
                    moves_applied=self.moves_applied,
                    node_lowerings=lowered, resumed=resumed)

    def _open(self) -> _Stream:
        if self._stream is None:
            self._stream = _Stream(self._client, self.id)
        return self._stream

    def _drop_stream(self) -> None:
        if self._stream is not None:
            self._stream.close()
            self._stream = None

    def _send_batches(self, batches: List[_Batch]) -> SendResult:
        pending: List[_Batch] = []  # sent, not acknowledged, in seq order
        todo = list(batches)
        lowered = 0
        resumed = 0
        last_ack: Any = None
        deadline: Optional[float] = None
        while todo or pending:
            try:
                stream = self._open()
                while todo and len(pending) < self.window:
                    batch = todo.pop(0)
                    stream.send(batch.data)
                    pending.append(batch)
                resp = stream.recv()
            except (grpc.RpcError, StopIteration) as e:
                deadline = self._stream_broke(e, deadline)
                last = self._wait_for_server(deadline)
                # Applied before the drop: acknowledged by the server's state.
                todo = [b for b in pending + todo if b.seq > last]
                pending = []
                resumed += 1
                continue
            deadline = None
            if resp.HasField("ack"):
                ack = resp.ack
                while pending and pending[0].seq <= ack.seq:
                    pending.pop(0)
                lowered += ack.node_lowerings
                last_ack = ack
            elif resp.HasField("error"):
                # The batch was not applied; the ones sent after it would
                # leave a gap: start over from the server's state next time.
                self._drop_stream()
                self._resync()
                raise _from_request_error(resp.error)
        self._next_seq = batches[-1].seq + 1 if batches else self._next_seq
        return SendResult(
            last_seq=self._next_seq - 1, batches=len(batches),
            moves_applied=last_ack.moves_applied if last_ack else
            self.moves_applied, node_lowerings=lowered,
            version=last_ack.version if last_ack else 0, resumed=resumed)

    def _stream_broke(self, e: Exception,
                      deadline: Optional[float]) -> float:
        """The stream failed with `e`: drops it, and raises the error unless
        a resume outlives it before `deadline` (set now when None); returns
        the deadline to resume within."""
        err = (_from_rpc(e) if isinstance(e, grpc.RpcError) else
               SwarfError(grpc.StatusCode.UNAVAILABLE, "the stream ended"))
        self._drop_stream()
        now = time.monotonic()
        deadline = deadline or now + self.resume_timeout
        if err.code not in _RESUMABLE or now > deadline:
            # A gap, another writer (ALREADY_EXISTS), a deleted session...:
            # the next send starts from the server's state.
            self._resync()
            raise err from None
        return deadline

    def _resync(self) -> None:
        """The next batch follows the server's last applied one."""
        try:
            self.refresh()
            self._next_seq = self.last_seq + 1
        except SwarfError:
            pass  # the caller raises the error that brought it here

    def _wait_for_server(self, deadline: float) -> int:
        """The session's last_seq once the server answers again."""
        delay = 0.05
        while True:
            try:
                self._info = self._client._stub.GetSession(
                    pb.GetSessionRequest(session_id=self.id),
                    metadata=self._client._md(self.id),
                    timeout=max(0.1, min(5.0, deadline - time.monotonic())),
                    wait_for_ready=True)
                return int(self._info.last_seq)
            except grpc.RpcError as e:
                if (e.code() not in _RESUMABLE + (
                        grpc.StatusCode.DEADLINE_EXCEEDED,) or
                        time.monotonic() > deadline):
                    raise _from_rpc(e) from None
            time.sleep(delay)
            delay = min(1.0, delay * 2)

    # -- reads

    def _tiles(self, window: Tuple[int, int, int, int], precision: Any,
               derivatives: bool, owners: bool,
               deviation: bool = False) -> Iterator[Any]:
        """The tiles holding the nodes [i0, i1) x [j0, j1), chosen by index
        so that no rounding of a region's edge can leave one out."""
        i0, i1, j0, j1 = window
        sel = pb.TileSelection()
        if (i0, i1, j0, j1) != (0, self.nx + 1, 0, self.ny + 1):
            if i0 >= i1 or j0 >= j1:
                return iter(())
            for ty in range(j0 // TILE_SIZE, (j1 - 1) // TILE_SIZE + 1):
                for tx in range(i0 // TILE_SIZE, (i1 - 1) // TILE_SIZE + 1):
                    sel.tiles.add(tx=tx, ty=ty)
        req = pb.GetTilesRequest(session_id=self.id, selection=sel,
                                 precision=precision,
                                 include_derivatives=derivatives,
                                 include_owners=owners,
                                 include_deviation=deviation)
        return self._client._stream("GetTiles", req, self.id)

    def _node_window(self, region: Optional[Sequence[float]]
                     ) -> Tuple[int, int, int, int]:
        """Node index ranges [i0, i1) x [j0, j1) inside `region`."""
        if region is None:
            return 0, self.nx + 1, 0, self.ny + 1
        x, y = self.node_x(), self.node_y()
        rx0, ry0, rx1, ry1 = (float(v) for v in region)
        ii = np.nonzero((x >= rx0) & (x <= rx1))[0]
        jj = np.nonzero((y >= ry0) & (y <= ry1))[0]
        if len(ii) == 0 or len(jj) == 0:
            return 0, 0, 0, 0
        return int(ii[0]), int(ii[-1]) + 1, int(jj[0]), int(jj[-1]) + 1

    def heights(self, region: Optional[Sequence[float]] = None,
                precision: str = "double", owners: bool = False) -> Heights:
        """Node heights (mm) as a 2-D array [j, i] with the node coordinates.

        Args:
          region: (x0, y0, x1, y1) mm: the nodes inside it; None: all.
          precision: "double" (the simulated heights, bit for bit) or
            "float" (float32, half the bytes).
          owners: also the id of the move that set each node.
        """
        if precision not in ("double", "float"):
            raise ValueError("precision must be 'double' or 'float'")
        dbl = precision == "double"
        i0, i1, j0, j1 = window = self._node_window(region)
        z = np.empty((j1 - j0, i1 - i0), np.float64 if dbl else np.float32)
        own = np.empty(z.shape, np.int32) if owners else None
        for t in self._tiles(window, pb.PRECISION_DOUBLE if dbl else
                             pb.PRECISION_FLOAT, False, owners):
            vals = np.asarray(t.heights_d if dbl else t.heights_f,
                              z.dtype).reshape(t.ny, t.nx)
            self._paste(z, vals, t, i0, i1, j0, j1)
            if own is not None:
                self._paste(own, np.asarray(t.owners, np.int32).reshape(
                    t.ny, t.nx), t, i0, i1, j0, j1)
        return Heights(self.node_x()[i0:i1], self.node_y()[j0:j1], z, own)

    @staticmethod
    def _paste(dst: npt.NDArray[Any], vals: npt.NDArray[Any], t: Any,
               i0: int, i1: int, j0: int, j1: int) -> None:
        a0, a1 = max(i0, t.i0), min(i1, t.i0 + t.nx)
        b0, b1 = max(j0, t.j0), min(j1, t.j0 + t.ny)
        if a0 < a1 and b0 < b1:
            dst[b0 - j0:b1 - j0, a0 - i0:a1 - i0] = \
                vals[b0 - t.j0:b1 - t.j0, a0 - t.i0:a1 - t.i0]

    def jets(self, region: Optional[Sequence[float]] = None) -> Jets:
        """Heights and derivatives per node (taylor sessions; a zmap
        session raises FAILED_PRECONDITION)."""
        i0, i1, j0, j1 = window = self._node_window(region)
        shape = (j1 - j0, i1 - i0)
        out: Dict[str, npt.NDArray[Any]] = {"w": np.empty(shape, np.float64)}
        for name in ("wx", "wy", "wxx", "wxy", "wyy"):
            out[name] = np.empty(shape, np.float32)
        for t in self._tiles(window, pb.PRECISION_DOUBLE, True, False):
            for name, arr in out.items():
                src = t.heights_d if name == "w" else getattr(t, name)
                self._paste(arr, np.asarray(src, arr.dtype).reshape(
                    t.ny, t.nx), t, i0, i1, j0, j1)
        return Jets(self.node_x()[i0:i1], self.node_y()[j0:j1], **out)

    def error_stats(self, region: Optional[Sequence[float]] = None,
                    samples_per_edge: int = 0,
                    map: Optional[Tuple[int, int]] = None) -> ErrorStats:
        """The scheme's error against the exact surface (mm).

        Args:
          region: (x0, y0, x1, y1) mm; None: the whole stock.
          samples_per_edge: n x n samples per element minus the corners
            (0: 5, the paper's 21 samples); in [2, 64].
          map: (cols, rows) of an error map over the region, returned as a
            (rows, cols) float32 array.
        """
        cols, rows = map if map is not None else (0, 0)
        req = pb.GetErrorStatsRequest(session_id=self.id,
                                      samples_per_edge=samples_per_edge,
                                      map_cols=cols, map_rows=rows)
        rect = _rect(region)
        if rect is not None:
            req.region.CopyFrom(rect)
        r = self._client._call("GetErrorStats", req, self.id)
        m = None
        if r.map_cols > 0:
            m = np.asarray(r.map_max_error, np.float32).reshape(
                r.map_rows, r.map_cols)
        return ErrorStats(_SCHEME_NAMES.get(r.scheme, "guarded"), r.max_error,
                          r.mean_error, r.rms_error, (r.max_x, r.max_y),
                          r.samples, m)

    def marks(self, region: Optional[Sequence[float]] = None,
              screening_threshold: float = 0.0,
              min_angle_deg: float = 0.0) -> List[Mark]:
        """Cutting marks (taylor sessions), one Mark per polyline."""
        req = pb.GetCuttingMarksRequest(
            session_id=self.id, screening_threshold=screening_threshold,
            min_angle_deg=min_angle_deg)
        rect = _rect(region)
        if rect is not None:
            req.region.CopyFrom(rect)
        return [Mark(np.asarray(p.xyz, np.float64).reshape(-1, 3),
                     tuple(p.owners), np.asarray(p.angle_deg, np.float64),
                     p.closed)
                for p in self._client._stream("GetCuttingMarks", req, self.id)]

    def probe(self, xy: ArrayLike) -> ProbeResult:
        """Heights, normals and owners at points xy (N, 2) mm (sent in
        chunks, so any N works)."""
        pts = np.ascontiguousarray(xy, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             f"xy must have shape (N, 2), got {pts.shape}")
        h, n, o = [], [], []
        for start in range(0, max(len(pts), 1), PROBE_CHUNK_POINTS):
            chunk = pts[start:start + PROBE_CHUNK_POINTS]
            r = self._client._call("Probe", pb.ProbeRequest(
                session_id=self.id, xy=chunk.ravel().tolist()), self.id)
            h.append(np.asarray(r.heights, np.float64))
            n.append(np.asarray(r.normals, np.float64).reshape(-1, 3))
            o.append(np.asarray(r.owners, np.int64))
        return ProbeResult(np.concatenate(h), np.concatenate(n),
                           np.concatenate(o))

    # -- the design

    def set_design(self, design: Union[str, bytes, ArrayLike], *,
                   units: str = "mm",
                   offset: Sequence[float] = (0.0, 0.0, 0.0),
                   name: Optional[str] = None) -> DesignInfo:
        """Sets the part as designed, replacing any earlier one: a path or
        the bytes of an STL or STEP file, or triangles (T, 3, 3) mm (sent as
        a binary STL). Uploaded in chunks of DESIGN_CHUNK_BYTES; kept with
        the session on the server (journaled, restored, deleted with it)."""
        if units not in ("mm", "inch"):
            raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                             f"units must be mm or inch, got {units!r}")
        if isinstance(design, (str, bytes)):
            data = _read(design)
            assert data is not None
            label = name or (design if isinstance(design, str) else "design")
        else:
            tris = np.ascontiguousarray(design, dtype=np.float32)
            if tris.ndim != 3 or tris.shape[1:] != (3, 3):
                raise SwarfError(grpc.StatusCode.INVALID_ARGUMENT,
                                 "triangles must have shape (T, 3, 3), got "
                                 f"{tris.shape}")
            rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", 9),
                                             ("a", "<u2")])
            rec["v"] = tris.reshape(-1, 9)
            data = (b"swarf_client triangles".ljust(80) +
                    np.uint32(len(tris)).tobytes() + rec.tobytes())
            label = name or "triangles"
        ox, oy, oz = (float(v) for v in offset)
        info = None
        for start in range(0, max(len(data), 1), DESIGN_CHUNK_BYTES):
            chunk = data[start:start + DESIGN_CHUNK_BYTES]
            last = start + DESIGN_CHUNK_BYTES >= len(data)
            req = pb.SetDesignRequest(
                session_id=self.id, offset=start, data=chunk, last=last,
                scale=25.4 if units == "inch" else 1.0, name=label)
            req.translation.CopyFrom(pb.Point3(x=ox, y=oy, z=oz))
            info = self._client._call("SetDesign", req, self.id)
        assert info is not None
        return DesignInfo(info.name, info.triangles, info.covered_nodes,
                          (info.min.x, info.min.y, info.min.z),
                          (info.max.x, info.max.y, info.max.z))

    def deviation(self, *, allowance: float = 0.0,
                  tolerance: Optional[float] = None,
                  samples_per_edge: Optional[int] = None,
                  max_moves: int = 0) -> Deviation:
        """The machined surface against the design (set_design first):
        gouge and excess, vertical and normal, the verdict at `tolerance`
        (default 0.01 mm) with `allowance`, and the moves that gouge."""
        opts = pb.DeviationRequest(allowance=allowance, max_moves=max_moves)
        if tolerance is not None:
            opts.tolerance.value = tolerance
        if samples_per_edge is not None:
            opts.samples_per_edge.value = samples_per_edge
        req = pb.GetDeviationRequest(session_id=self.id, options=opts)
        r = self._client._call("GetDeviation", req, self.id)

        def moves(ms: Any) -> List[DeviationMove]:
            return [DeviationMove(int(m.move), m.depth, m.x, m.y, m.area_mm2)
                    for m in ms]
        return Deviation(
            r.triangles, r.nodes, r.samples, r.gouge_max,
            (r.gouge_x, r.gouge_y), int(r.gouge_move), r.gouge_volume_mm3,
            r.excess_max, (r.excess_x, r.excess_y), r.excess_mean,
            r.excess_volume_mm3, r.normal_gouge_max, r.normal_excess_max,
            r.allowance, r.tolerance, r.out_of_tolerance_area_mm2, r.ok,
            moves(r.gouge_moves), moves(r.excess_moves))

    def deviation_map(self, region: Optional[Sequence[float]] = None
                      ) -> Heights:
        """Per node, the vertical deviation from the design z - z_d (mm,
        float32; positive excess, negative gouge, NaN where no design lies
        above), as Heights(x, y, z=the deviations)."""
        i0, i1, j0, j1 = window = self._node_window(region)
        dev = np.empty((j1 - j0, i1 - i0), np.float32)
        for t in self._tiles(window, pb.PRECISION_FLOAT, False, False, True):
            self._paste(dev, np.asarray(t.deviation, np.float32).reshape(
                t.ny, t.nx), t, i0, i1, j0, j1)
        return Heights(self.node_x()[i0:i1], self.node_y()[j0:j1], dev, None)

    # -- lifetime

    def delete(self) -> None:
        """Deletes the session and its files on the server."""
        self._drop_stream()
        self._client._call("DeleteSession", pb.DeleteSessionRequest(
            session_id=self.id), self.id)

    def close(self) -> None:
        """Closes the session's stream (the session stays)."""
        self._drop_stream()

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc: Any) -> None:
        self._drop_stream()
        if self.delete_on_exit:
            self.delete()
