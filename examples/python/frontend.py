"""A CAM frontend in 40 lines: a program's tool tips (G0/G1 with X/Y/Z words,
tool changes T.. M6) through swarf_client, then the heights as a .npy and the
cutting marks as a plot (if matplotlib is there).
usage: frontend.py [PROGRAM] [HOST:PORT]   (swarfd must be running)
PROGRAM: examples/pocket.nc (the default) or vcarve.nc, written by
scripts/make-example, or bear.nc of the corpus beside the repository."""
import os, re, sys
import numpy as np
import swarf_client
from swarf_client import Ball, Cone, Flat

JOBS = {  # per program: the stock (x0, y0, x1, y1, top) and the tools (radii, mm)
    "pocket.nc": ((0, 0, 100, 80, 0), {1: Flat(3), 2: Flat(1.5), 3: Flat(0.5)}),
    "vcarve.nc": ((0, 0, 80, 80, 0), {1: Cone(3, half_angle_deg=30)}),
    "bear.nc": ((0, 0, 80, 80, 0), {1: Ball(3.175 / 2)}),  # a 1/8 in ball-end
}
here = os.path.dirname(os.path.abspath(__file__))
nc = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "pocket.nc")
stock, tools = JOBS[os.path.basename(nc)]
pos, tool, runs = {"X": 0.0, "Y": 0.0, "Z": 20.0}, 1, [(1, [])]  # [(tool, tips)]
for line in open(nc):
    line = re.sub(r"\(.*?\)|;.*", "", line.upper())  # comments out
    if re.search(r"M0*6(?!\d)", line) and (t := re.search(r"T(\d+)", line)):
        tool = int(t.group(1))
        runs.append((tool, []))
    words = re.findall(r"([XYZ])(-?\d*\.?\d+)", line)
    if words:
        pos.update((k, float(v)) for k, v in words)
        runs[-1][1].append((pos["X"], pos["Y"], pos["Z"]))
with swarf_client.Client(sys.argv[2] if len(sys.argv) > 2 else "127.0.0.1:50051") as client:
    with client.create_session(stock, spacing=0.1, tools=tools, delete_on_exit=True) as s:
        for i, (tool, tips) in enumerate(r for r in runs if r[1]):
            # A tool's first tip after a change only places it.
            print(f"T{tool}", s.send(np.array(tips), tool=tool, reposition=i > 0))
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
