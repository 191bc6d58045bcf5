# Per-vertex colours of the machined surface: by height (a ramp from the
# lowest to the highest machined point) or by deviation from the design
# (as swarf's deviation.png: white within tolerance, gouge in reds, excess
# in blues, darker further out; grey where no design lies above). Kept as
# the Mesh feature's VertexColors (App::PropertyColorList), which FreeCAD's
# mesh view shows when its Coloring is on.

GREY = (0.6, 0.6, 0.6)
WHITE = (1.0, 1.0, 1.0)
# Vertices at most this far above the mesh's base are its bottom, not cut.
_BASE_EPS = 1e-9


def _ramp(t):
    """Blue (low) -> cyan -> green -> yellow -> red (high), t in [0, 1]."""
    t = min(max(t, 0.0), 1.0)
    stops = [(0.0, (0.1, 0.2, 0.9)), (0.25, (0.0, 0.8, 0.9)),
             (0.5, (0.1, 0.8, 0.2)), (0.75, (0.95, 0.85, 0.1)),
             (1.0, (0.9, 0.15, 0.1))]
    for (t0, c0), (t1, c1) in zip(stops, stops[1:]):
        if t <= t1:
            f = (t - t0) / (t1 - t0)
            return tuple(a + (b - a) * f for a, b in zip(c0, c1))
    return stops[-1][1]


def height_colors(points):
    """Points (with .z) -> colours; the base (the mesh's floor) grey."""
    zs = [p.z for p in points]
    if not zs:
        return []
    base = min(zs)
    cut = [z for z in zs if z > base + _BASE_EPS]
    lo, hi = (min(cut), max(cut)) if cut else (base, base)
    span = hi - lo
    return [GREY if z <= base + _BASE_EPS else
            _ramp((z - lo) / span if span > 0 else 1.0) for z in zs]


def deviation_values(points, design, spacing, tolerance):
    """z - z_design for each point (None where no design is above it or at
    the mesh's floor), z_design the design mesh's top envelope (its first
    face on a downward ray). On a wall the vertical figure is meaningless
    (the wall's foot lies under the design's top): a point that would be a
    gouge takes the smallest deviation found one grid spacing around it,
    0 where the design ends there (the wall stands where it should)."""
    zs = [p.z for p in points]
    base = min(zs) if zs else 0.0
    top = design.BoundBox.ZMax + 1.0

    def dz(x, y, z):
        hit = design.nearestFacetOnRay((x, y, top), (0.0, 0.0, -1.0))
        return z - max(v[2] for v in hit.values()) if hit else None

    out = []
    for p in points:
        if p.z <= base + _BASE_EPS:
            out.append(None)
            continue
        v = dz(p.x, p.y, p.z)
        if v is not None and v < -tolerance:
            for ox, oy in ((spacing, 0), (-spacing, 0), (0, spacing),
                           (0, -spacing)):
                w = dz(p.x + ox, p.y + oy, p.z)
                w = 0.0 if w is None else w
                if abs(w) < abs(v):
                    v = w
        out.append(v)
    return out


def deviation_colors(values, tolerance, allowance):
    gouges = [-v for v in values if v is not None and v < -tolerance]
    excess = [v for v in values if v is not None and v > allowance + tolerance]
    gmax = max(gouges) if gouges else 0.0
    emax = max(excess) if excess else 0.0
    colors = []
    for v in values:
        if v is None:
            colors.append(GREY)
        elif v < -tolerance:
            f = (-v - tolerance) / (gmax - tolerance) if gmax > tolerance else 1
            f = 0.25 + 0.75 * min(f, 1.0)
            colors.append((1.0 - 0.3 * f, 1.0 - f, 1.0 - f))
        elif v > allowance + tolerance:
            lo = allowance + tolerance
            f = (v - lo) / (emax - lo) if emax > lo else 1
            f = 0.25 + 0.75 * min(f, 1.0)
            colors.append((1.0 - f, 1.0 - 0.7 * f, 1.0 - 0.2 * f))
        else:
            colors.append(WHITE)
    return colors
