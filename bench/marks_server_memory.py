#!/usr/bin/python3
"""swarfd's peak memory while it serves a session's cutting marks (issue 28).

Not a ctest: a measurement (docs/benchmarks.md, "swarfd streams the marks").
Starts SWARFD (memory only, on a free port), cuts PROGRAM into a guarded
session of the 300 mm plate's stock and tools (out/plate-300: 300 x 300 mm,
0.05 mm, T1 flat d=10, T2 ball d=4, T3 ball d=1; the server interprets the
program), then for each MODE resets swarfd's peak resident set
(/proc/PID/clear_refs) and fetches the marks, reading each polyline and
keeping only counts:
  cli     as `swarf run` does (client/cli/run_report.cc FetchMarks): a
          Simulate MarksRequest, then GetCuttingMarks when that is
          RESOURCE_EXHAUSTED;
  stream  GetCuttingMarks alone.
Prints swarfd's VmRSS before and VmHWM during each. Needs grpcio and
grpcio-tools (python3-grpcio, python3-grpc-tools).

usage: bench/marks_server_memory.py SWARFD PROGRAM MODE...
"""
import os
import socket
import subprocess
import sys
import tempfile
import time

import grpc
from grpc_tools import protoc

SID = 'plate300'


def main():
    swarfd, program, modes = sys.argv[1], sys.argv[2], sys.argv[3:] or ['cli']
    gen = tempfile.mkdtemp()
    proto = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..',
                         'proto')
    if protoc.main(['protoc', '-I' + proto, '--python_out=' + gen,
                    '--grpc_python_out=' + gen,
                    os.path.join(proto, 'swarf/v1/swarf.proto')]) != 0:
        sys.exit('protoc failed')
    sys.path.insert(0, gen)
    from swarf.v1 import swarf_pb2 as pb, swarf_pb2_grpc as rpc

    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    server = subprocess.Popen(
        [swarfd, f'--listen=127.0.0.1:{port}', '--data_dir='],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        opts = [('grpc.max_receive_message_length', -1),
                ('grpc.max_send_message_length', -1)]
        channel = grpc.insecure_channel(f'127.0.0.1:{port}', options=opts)
        grpc.channel_ready_future(channel).result(timeout=30)
        stub = rpc.SwarfStub(channel)
        md = (('x-swarf-session', SID),)

        def status(key):  # MiB
            with open(f'/proc/{server.pid}/status') as f:
                for line in f:
                    if line.startswith(key + ':'):
                        return int(line.split()[1]) // 1024
            return 0

        req = pb.CreateSessionRequest(session_id=SID, spacing=0.05,
                                      scheme=pb.SCHEME_GUARDED)
        req.stock.x1, req.stock.y1 = 300, 300
        for tool, shape, radius in ((1, 'flat', 5), (2, 'ball', 2),
                                    (3, 'ball', 0.5)):
            t = req.tools.add()
            t.id = tool
            getattr(t, shape).radius = radius
        s = stub.CreateSession(req, metadata=md)
        print(f'session {s.nx} x {s.ny} elements', flush=True)

        with open(program, 'rb') as f:
            data = f.read()
        chunk = 8 << 20

        def upload():
            for off in range(0, len(data), chunk):
                r = pb.SimulateRequest()
                r.program.request_id = 1
                r.program.offset = off
                r.program.data = data[off:off + chunk]
                r.program.last = off + chunk >= len(data)
                r.program.options.name = os.path.basename(program)
                yield r

        t0 = time.time()
        for resp in stub.Simulate(upload(), metadata=md):
            if resp.HasField('error'):
                sys.exit(f'error: {resp.error}')
            if resp.HasField('program_done'):
                print(f'program: {resp.program_done.moves} moves in '
                      f'{time.time() - t0:.1f} s', flush=True)
        print(f'swarfd after the cut: VmRSS {status("VmRSS")} MiB, VmHWM '
              f'{status("VmHWM")} MiB', flush=True)

        for mode in modes:
            time.sleep(1)
            base = status('VmRSS')
            with open(f'/proc/{server.pid}/clear_refs', 'w') as f:
                f.write('5')  # VmHWM := VmRSS
            t0 = time.time()
            code = 8
            if mode == 'cli':
                r = pb.SimulateRequest()
                r.marks.request_id = 1
                for resp in stub.Simulate(iter([r]), metadata=md):
                    if resp.HasField('error'):
                        code = resp.error.code
                        print(f'  MarksRequest: code {code}: '
                              f'{resp.error.message}', flush=True)
                    elif resp.HasField('polylines'):
                        code = 0
                        print(f'  MarksRequest: '
                              f'{len(resp.polylines.polylines)} polylines',
                              flush=True)
            if code == 8:
                n = v = 0
                for p in stub.GetCuttingMarks(
                        pb.GetCuttingMarksRequest(session_id=SID),
                        metadata=md):
                    n += 1
                    v += len(p.xyz) // 3
                print(f'  GetCuttingMarks: {n} polylines, {v} vertices',
                      flush=True)
            print(f'{mode}: {time.time() - t0:.1f} s; swarfd VmRSS before '
                  f'{base} MiB, peak during {status("VmHWM")} MiB '
                  f'(+{status("VmHWM") - base}), after {status("VmRSS")} MiB',
                  flush=True)
    finally:
        server.terminate()
        server.wait()


if __name__ == '__main__':
    main()
