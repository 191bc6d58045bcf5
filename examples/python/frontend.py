"""A CAM frontend in under 40 lines: a G-code program interpreted and simulated by
swarfd (Session.run_program: the server's interpreter, as `swarf run`), then
the heights as a .npy and the cutting marks as a plot (if matplotlib is
there).
usage: frontend.py [PROGRAM] [HOST:PORT]   (swarfd must be running)
PROGRAM: examples/pocket.nc (the default) or vcarve.nc, written by
scripts/make-example, or bear.nc of the corpus beside the repository."""
import os, sys
import numpy as np
import swarf_client
from swarf_client import Ball, Cone, Flat

JOBS = {  # per program: the stock (x0, y0, x1, y1, top) and the tools by T number
    "pocket.nc": ((0, 0, 100, 80, 0), {1: Flat(3), 2: Flat(1.5), 3: Flat(0.5)}),
    "vcarve.nc": ((0, 0, 80, 80, 0), {1: Cone(3, half_angle_deg=30)}),
    "bear.nc": ((0, 0, 80, 80, 0), {1: Ball(3.175 / 2)}),  # a 1/8 in ball-end
}
here = os.path.dirname(os.path.abspath(__file__))
nc = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "pocket.nc")
stock, tools = JOBS[os.path.basename(nc)]
with swarf_client.Client(sys.argv[2] if len(sys.argv) > 2 else "127.0.0.1:50051") as client:
    with client.create_session(stock, spacing=0.1, tools=tools, delete_on_exit=True) as s:
        # The program's T numbers are the session's tool ids; progress per batch.
        done = s.run_program(nc, progress=lambda ack: print(f"batch {ack.seq}: "
                                                             f"{ack.moves_applied} moves", end="\r"))
        print(f"\n{done.moves} moves from {done.source_lines} lines", *done.warnings, sep="\n")
        h, marks = s.heights(), s.marks()
name = os.path.splitext(os.path.basename(nc))[0]
np.save(f"{name}-heights.npy", h.z)  # [j, i] at (h.x[i], h.y[j]), mm
try:
    import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
    plt.imshow(h.z, origin="lower", cmap="gray", extent=(h.x[0], h.x[-1], h.y[0], h.y[-1]))
    if marks:
        xy = np.concatenate([np.vstack([m.xyz[:, :2], [np.nan, np.nan]]) for m in marks])
        plt.plot(xy[:, 0], xy[:, 1], "r-", lw=0.2)  # NaN rows split the marks
    plt.savefig(f"{name}-marks.png", dpi=200)
except ImportError:
    print(f"{len(marks)} marks; install python3-matplotlib for {name}-marks.png")
