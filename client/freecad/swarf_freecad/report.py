# The report of one run, from swarf's stats.json (README: "Is the part
# right?", "Will it crash?") with every program line it cites followed by
# the operation and the Path command that made it. Pure: no FreeCAD.

WORST = 5  # lines listed per finding
_SAFETY = (
    ("rapid_cuts", "rapid moves cutting material"),
    ("shank_contacts", "shank in material"),
    ("holder_contacts", "holder in material"),
    ("center_plunges", "plunges of a tool not cutting at its centre"),
    ("below_floor", "moves below the floor"),
    ("outside_limits", "moves outside the machine's limits"),
)


def where(line, lines):
    """'line N (OPERATION, command I: G1 X..)' for a posted line."""
    if line is None:
        return "no line"
    hit = lines.get(int(line))
    if hit is None:
        return "line %d" % int(line)
    op, index, gcode = hit
    return "line %d (%s, command %d: %s)" % (int(line), op, index + 1, gcode)


def _g(x):
    return "%.4g" % x


def verdict(stats):
    d = stats.get("deviation")
    if not d:
        return "no design compared (the Job has no model)"
    n = d.get("normal", {})
    state = "within tolerance" if d.get("ok") else "OUT OF TOLERANCE"
    text = ("%s (tolerance %s mm, allowance %s mm): gouge %s mm, excess %s mm"
            % (state, _g(d.get("tolerance", 0)), _g(d.get("allowance", 0)),
               _g(n.get("gouge_max", 0)), _g(n.get("excess_max", 0))))
    out = d.get("out_of_tolerance", {})
    if out.get("area_mm2"):
        text += ", %s mm2 out of tolerance" % _g(out["area_mm2"])
    return text


def report(job_label, stats, lines, returncode=0):
    r = []
    r.append("swarf: Job %s: %d moves from %d lines, stock %s" % (
        job_label, stats.get("moves", 0), stats.get("source_lines", 0),
        "[{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] top {top:g} mm, "
        "{nx} x {ny} elements".format(**stats["stock"])
        if "stock" in stats else "?"))
    tools = stats.get("tools", {})
    if tools:
        r.append("tools: " + ", ".join("T%s %s" % kv for kv in sorted(
            tools.items(), key=lambda kv: int(kv[0]))))
    r.append("verdict: " + verdict(stats))
    d = stats.get("deviation")
    if d:
        gouging = d.get("out_of_tolerance", {}).get("lines", [])
        if gouging:
            r.append("worst gouging lines:")
            for g in gouging[:WORST]:
                r.append("  gouge %s mm at (%s, %s), %s mm2: %s" % (
                    _g(g["gouge_max"]), _g(g["x"]), _g(g["y"]),
                    _g(g.get("area_mm2", 0)), where(g.get("line"), lines)))
        g = d.get("gouge", {})
        if g.get("max", 0) > 0:
            r.append("deepest vertical gouge (dz: on a wall the normal "
                     "distance above is what counts) %s mm at (%s, %s): %s" % (
                _g(g["max"]), _g(g["x"]), _g(g["y"]),
                where(g.get("line"), lines)))
        excess = sorted(d.get("excess", {}).get("lines", []),
                        key=lambda e: -e["excess_max"])
        if excess:
            r.append("most material left (excess) by line:")
            for e in excess[:WORST]:
                r.append("  excess %s mm at (%s, %s): %s" % (
                    _g(e["excess_max"]), _g(e["x"]), _g(e["y"]),
                    where(e.get("line"), lines)))
    safety = stats.get("safety")
    if safety:
        counts = safety.get("counts", {})
        found = [(k, t) for k, t in _SAFETY if counts.get(k)]
        if not found:
            r.append("safety: no rapid cuts, shank or holder contacts, "
                     "centre plunges, floor or limit violations")
        for key, title in found:
            items = safety.get(key, [])
            r.append("safety: %d %s; the first:" % (counts[key], title))
            for it in items[:WORST]:
                r.append("  %s mm deep at (%s, %s, %s), %s mm3: %s" % (
                    _g(it.get("depth", 0)), _g(it["x"]), _g(it["y"]),
                    _g(it["z"]), _g(it.get("volume_mm3", 0)),
                    where(it.get("line"), lines)))
        missing = safety.get("tools_without_assembly", [])
        if missing:
            r.append("note: no flute length for T%s: no shank check there" %
                     ", T".join(str(t) for t in missing))
    outside = stats.get("outside_stock")
    if outside:
        r.append("warning: " + outside.get("message", ""))
    if stats.get("dropped_moves"):
        r.append("warning: %d moves dropped" % stats["dropped_moves"])
    process = stats.get("process")
    if process:
        r.append("cycle time %.1f s, removed %s mm3" % (
            process.get("cycle_time_s", 0), _g(process.get("removed_mm3", 0))))
    if returncode == 3:
        r.append("(swarf exited 3: out of tolerance or a safety finding)")
    return "\n".join(r) + "\n"
