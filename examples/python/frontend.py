"""A CAM frontend in 20 lines: bear.nc's tips through swarf_client, then the
heights as a .npy and the cutting marks as a plot (if matplotlib is there).
usage: frontend.py [bear.nc] [host:port]   (swarfd must be running)"""
import re, sys
import numpy as np
import swarf_client

nc = sys.argv[1] if len(sys.argv) > 1 else "../shared/corpus/bear.nc"
pos, tips = {"X": 0.0, "Y": 0.0, "Z": 20.0}, []
for line in open(nc):  # G0/G1 with modal X/Y/Z words: all bear.nc has
    words = re.findall(r"([XYZ])(-?\d*\.?\d+)", line.upper())
    if words:
        pos.update((k, float(v)) for k, v in words)
        tips.append((pos["X"], pos["Y"], pos["Z"]))
with swarf_client.Client(sys.argv[2] if len(sys.argv) > 2 else "127.0.0.1:50051") as client:
    with client.create_session((0, 0, 80, 80, 0), spacing=0.1, tools={1: 3.175 / 2},
                               delete_on_exit=True) as s:  # 1/8 in ball-end
        print(s.send(np.array(tips)))
        h, marks = s.heights(), s.marks()
np.save("bear-heights.npy", h.z)  # [j, i] at (h.x[i], h.y[j]), mm
try:
    import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
    plt.imshow(h.z, origin="lower", cmap="gray", extent=(h.x[0], h.x[-1], h.y[0], h.y[-1]))
    xy = np.concatenate([np.vstack([m.xyz[:, :2], [np.nan, np.nan]]) for m in marks])
    plt.plot(xy[:, 0], xy[:, 1], "r-", lw=0.2)  # NaN rows split the marks
    plt.savefig("bear-marks.png", dpi=200)
except ImportError:
    print(f"{len(marks)} marks; install python3-matplotlib for bear-marks.png")
