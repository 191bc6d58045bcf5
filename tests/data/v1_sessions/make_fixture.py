#!/usr/bin/python3
"""Writes the v1_sessions fixture: sessions journaled by a real swarfd of
commit 5d6008b (snapshot state format "SWARFWP1"), each with a snapshot
taken mid-job and journal batches after it.

  make_fixture.py --swarfd OLD/build/bin/swarfd --proto OLD/proto --out DIR

Starts that swarfd on an empty data dir with --snapshot_every_moves=250,
creates the sessions of SESSIONS, streams their batches (every point from
Points(), below; tests/legacy_restore_test.cc computes the same points with
the same arithmetic), asks the old server for each session's counters and a
digest of its tiles (expected.txt), kills it with SIGKILL (no snapshot at
exit, as in a crash), checkpoints each journal's WAL into its .db (sqlite3,
so the .db alone holds every batch) and copies <id>.db and <id>.snap to DIR.
Needs Debian's python3-grpcio and python3-grpc-tools (/usr/bin/python3).
"""

import argparse
import os
import re
import shutil
import signal
import sqlite3
import struct
import subprocess
import sys
import tempfile
import time

SNAPSHOT_EVERY_MOVES = 250

# id, scheme, stock (x0, y0, x1, y1, z_top), nx, ny, tools {id: radius},
# raster (points per row, x step, y step), batches [(tool, reposition,
# points)], the points of consecutive batches following one raster path.
SESSIONS = [
    ("v1-taylor", "SCHEME_TAYLOR", (-2.0, 1.0, 6.0, 5.0, 10.0), 80, 40,
     {1: 0.5, 2: 0.25}, (60, 0.12, 0.2),
     [(1, False, 40)] * 8 + [(2, True, 40)] + [(2, False, 40)] * 3),
    ("v1-guarded", "SCHEME_GUARDED", (0.0, 0.0, 4.0, 4.0, 0.0), 40, 40,
     {1: 0.4}, (30, 0.12, 0.15), [(1, False, 30)] * 12),
    ("v1-zmap", "SCHEME_ZMAP", (0.0, 0.0, 4.0, 4.0, 0.0), 40, 40,
     {1: 0.3}, (30, 0.12, 0.15), [(1, False, 36)] * 10),
]


def Points(stock, raster, first, count):
  """Points first..first+count-1 of a session's zig-zag raster (only +, *,
  / and integer % on IEEE doubles: C++ computes the same bits)."""
  x0, y0, _, _, z_top = stock
  per_row, sx, sy = raster
  out = []
  for k in range(first, first + count):
    row = k // per_row
    col = k % per_row
    u = col if row % 2 == 0 else per_row - 1 - col
    x = x0 + 0.3 + u * sx
    y = y0 + 0.3 + row * sy
    z = z_top - 0.3 - 0.1 * ((row * 5 + u * 3) % 7) / 6
    out += [x, y, z]
  return out


def Fnv1a(h, data):
  for b in data:
    h = ((h ^ b) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
  return h


def TilesDigest(stub, pb, sid, derivatives):
  """FNV-1a 64 over every tile (GetTiles order): tx, ty (i32), version
  (u64), heights (f64), owners (i32), wx, wy, wxx, wxy, wyy (f32; zeros
  without derivatives), little-endian."""
  req = pb.GetTilesRequest(session_id=sid, precision=pb.PRECISION_DOUBLE,
                           include_derivatives=derivatives,
                           include_owners=True)
  h = 0xcbf29ce484222325
  tiles = 0
  for t in stub.GetTiles(req, metadata=[("x-swarf-session", sid)]):
    n = t.nx * t.ny
    buf = struct.pack("<iiQ", t.tx, t.ty, t.version)
    buf += struct.pack("<%dd" % n, *t.heights_d)
    buf += struct.pack("<%di" % n, *t.owners)
    for d in (t.wx, t.wy, t.wxx, t.wxy, t.wyy):
      vals = list(d) if len(d) else [0.0] * n
      buf += struct.pack("<%df" % n, *vals)
    h = Fnv1a(h, buf)
    tiles += 1
  return h, tiles


def main():
  ap = argparse.ArgumentParser()
  ap.add_argument("--swarfd", required=True)
  ap.add_argument("--proto", required=True)
  ap.add_argument("--out", required=True)
  args = ap.parse_args()

  tmp = tempfile.mkdtemp(prefix="swarf-v1-fixture-")
  gen = os.path.join(tmp, "gen")
  os.makedirs(gen)
  subprocess.check_call([
      sys.executable, "-m", "grpc_tools.protoc", "-I", args.proto,
      "--python_out", gen, "--grpc_python_out", gen,
      os.path.join(args.proto, "swarf/v1/swarf.proto")])
  sys.path.insert(0, gen)
  import grpc
  from swarf.v1 import swarf_pb2 as pb
  from swarf.v1 import swarf_pb2_grpc as pb_grpc

  data = os.path.join(tmp, "data")
  log_path = os.path.join(tmp, "swarfd.log")
  log = open(log_path, "w")
  server = subprocess.Popen(
      [args.swarfd, "--listen", "127.0.0.1:0", "--data_dir=" + data,
       "--journal_sync=full", "--worker_threads=2",
       "--snapshot_every_moves=%d" % SNAPSHOT_EVERY_MOVES],
      stdout=log, stderr=subprocess.STDOUT)
  try:
    port = None
    for _ in range(400):
      time.sleep(0.025)
      m = re.search(r"\(port (\d+)\)", open(log_path).read())
      if m:
        port = int(m.group(1))
        break
    assert port, open(log_path).read()
    stub = pb_grpc.SwarfStub(grpc.insecure_channel("127.0.0.1:%d" % port))
    expected = []
    for sid, scheme, stock, nx, ny, tools, raster, batches in SESSIONS:
      md = [("x-swarf-session", sid)]
      req = pb.CreateSessionRequest(
          session_id=sid, nx=nx, ny=ny, scheme=getattr(pb, scheme),
          stock=pb.Stock(x0=stock[0], y0=stock[1], x1=stock[2], y1=stock[3],
                         z_top=stock[4]))
      for tid, r in sorted(tools.items()):
        req.tools.add(id=tid, ball=pb.BallEnd(radius=r))
      stub.CreateSession(req, metadata=md)
      requests = []
      first = 0
      for seq, (tool, reposition, count) in enumerate(batches, start=1):
        requests.append(pb.SimulateRequest(moves=pb.MoveBatch(
            seq=seq, tool_id=tool, reposition=reposition,
            xyz=Points(stock, raster, first, count))))
        first += count
      acks = [r.ack for r in stub.Simulate(iter(requests), metadata=md)
              if r.HasField("ack")]
      assert [a.seq for a in acks] == list(range(1, len(batches) + 1)), acks
      s = stub.GetSession(pb.GetSessionRequest(session_id=sid), metadata=md)
      digest, tiles = TilesDigest(stub, pb, sid,
                                  scheme != "SCHEME_ZMAP")
      print("%s: last_seq %d snapshot_seq %d moves %d version %d tiles %d "
            "digest %016x" % (sid, s.last_seq, s.snapshot_seq,
                              s.moves_applied, s.version, tiles, digest))
      assert 0 < s.snapshot_seq < s.last_seq, "no journal tail after the snapshot"
      expected.append("%s %d %d %d %d %016x" % (
          sid, s.last_seq, s.snapshot_seq, s.moves_applied, s.version,
          digest))
  finally:
    server.send_signal(signal.SIGKILL)
    server.wait()
  os.makedirs(args.out, exist_ok=True)
  for sid, *_ in SESSIONS:
    db = os.path.join(data, sid + ".db")
    con = sqlite3.connect(db)
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()  # the last connection: sqlite removes -wal and -shm
    for suffix in ("-wal", "-shm"):
      assert not os.path.exists(db + suffix), db + suffix
    shutil.copyfile(db, os.path.join(args.out, sid + ".db"))
    shutil.copyfile(os.path.join(data, sid + ".snap"),
                    os.path.join(args.out, sid + ".snap"))
  with open(os.path.join(args.out, "expected.txt"), "w") as f:
    f.write("# id last_seq snapshot_seq moves_applied version "
            "tiles_digest (old swarfd, before the kill)\n")
    f.write("\n".join(expected) + "\n")
  shutil.rmtree(tmp)


if __name__ == "__main__":
  main()
