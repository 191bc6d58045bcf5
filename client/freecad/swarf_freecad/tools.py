# Tool controllers' ToolBits as swarf tools, written as a LinuxCNC tool table
# (`swarf run --tools`, README "Tools"): one line per tool number,
#   T1 P1 D5 ;flat flute=30 shank=3
# the shape and its keys in the comment. Lengths in mm, angles INCLUDED
# (FreeCAD's CuttingEdgeAngle and TipAngle are full angles too).
import os

from .compat import SwarfError

# ToolBit shape (the shape file's name) -> how it is simulated.
SUPPORTED = ("endmill", "ballend", "bullnose", "chamfer", "v-bit", "drill")


def _mm(value):
    """A FreeCAD Quantity or a number, as mm (float)."""
    if hasattr(value, "getValueAs"):
        return float(value.getValueAs("mm"))
    return float(value)


def _deg(value):
    if hasattr(value, "getValueAs"):
        return float(value.getValueAs("deg"))
    return float(value)


def _num(x):
    """Shortest exact-enough text for a key value (swarf reads doubles)."""
    return repr(float(x)) if x != int(x) else str(int(x))


def shape_name(bit):
    """The ToolBit's shape: its ShapeName, else its shape file's name."""
    name = getattr(bit, "ShapeName", "") or ""
    if not name:
        name = os.path.splitext(os.path.basename(getattr(bit, "BitShape", "") or ""))[0]
    # 0.20's ShapeName is the file's name with "_" for "-" (v_bit).
    return name.lower().replace("_", "-")


def _describe(tc, bit):
    return 'ToolBit "%s" (tool controller "%s", T%d)' % (
        getattr(bit, "Label", "?"), tc.Label, int(tc.ToolNumber))


def _legacy_tool(tc, tool):
    """0.20's legacy Path.Tool (ToolType) where a Job still uses one."""
    kind = getattr(tool, "ToolType", "")
    d = float(tool.Diameter)
    if kind == "EndMill":
        return "flat", {}, d
    if kind == "BallEndMill":
        return "ball", {}, d
    if kind in ("Drill", "CenterDrill", "CounterSink", "ChamferMill", "Engraver"):
        angle = float(getattr(tool, "CuttingEdgeAngle", 0) or 0)
        if not 0 < angle < 180:
            raise SwarfError('legacy tool "%s" (tool controller "%s"): %s with '
                             "CuttingEdgeAngle %g: swarf needs an included "
                             "angle in (0, 180)" % (tool.Name, tc.Label, kind,
                                                    angle))
        return "vbit", {"angle": angle}, d
    raise SwarfError('legacy tool "%s" (tool controller "%s"): tool type "%s" '
                     "has no swarf tool (EndMill, BallEndMill, Drill, "
                     "ChamferMill are simulated)" % (tool.Name, tc.Label, kind))


def swarf_tool(tc):
    """(shape, keys, diameter, assembly keys) of tool controller `tc`, or
    SwarfError naming the ToolBit."""
    bit = tc.Tool
    if bit is None:
        raise SwarfError('tool controller "%s" has no tool' % tc.Label)
    if not hasattr(bit, "BitShape") and hasattr(bit, "ToolType"):
        shape, keys, d = _legacy_tool(tc, bit)
        return shape, keys, d, {}
    name = shape_name(bit)
    where = _describe(tc, bit)
    if not hasattr(bit, "Diameter"):
        raise SwarfError("%s: shape \"%s\" has no Diameter" % (where, name))
    d = _mm(bit.Diameter)
    keys = {}
    if name == "endmill":
        shape = "flat"
    elif name == "ballend":
        shape = "ball"
    elif name == "bullnose":
        shape = "bull"
        if hasattr(bit, "CornerRadius"):
            keys["r"] = _mm(bit.CornerRadius)
        elif hasattr(bit, "FlatRadius"):
            # FlatRadius is the flat bottom's radius: the corner takes the rest.
            keys["r"] = d / 2 - _mm(bit.FlatRadius)
        else:
            raise SwarfError("%s: bullnose without FlatRadius or CornerRadius"
                             % where)
    elif name in ("chamfer", "v-bit", "vbit"):
        shape = "vbit"
        if not hasattr(bit, "CuttingEdgeAngle"):
            raise SwarfError("%s: %s without CuttingEdgeAngle" % (where, name))
        keys["angle"] = _deg(bit.CuttingEdgeAngle)
        tip = _mm(bit.TipDiameter) if hasattr(bit, "TipDiameter") else 0.0
        if tip > 0:
            keys["tip"] = tip
    elif name == "drill":
        # A drill is simulated as the cone of its point.
        shape = "vbit"
        if not hasattr(bit, "TipAngle"):
            raise SwarfError("%s: drill without TipAngle" % where)
        keys["angle"] = _deg(bit.TipAngle)
    else:
        raise SwarfError(
            "%s: shape \"%s\" has no swarf tool (swarf simulates %s)"
            % (where, name or "?", ", ".join(SUPPORTED)))
    assembly = {}
    if hasattr(bit, "CuttingEdgeHeight") and _mm(bit.CuttingEdgeHeight) > 0:
        assembly["flute"] = _mm(bit.CuttingEdgeHeight)
    if hasattr(bit, "ShankDiameter") and _mm(bit.ShankDiameter) > 0:
        assembly["shank"] = _mm(bit.ShankDiameter)
    return shape, keys, d, assembly


def table_line(number, shape, keys, diameter, assembly):
    words = [shape] + ["%s=%s" % (k, _num(v)) for k, v in keys.items()]
    words += ["%s=%s" % (k, _num(v)) for k, v in assembly.items()]
    return "T%d P%d D%s ;%s" % (number, number, _num(diameter), " ".join(words))


def tool_table(controllers):
    """The .tbl text for `controllers` (tool controllers as posted, each
    number once; a number given two different tools is an error, since the
    program selects tools by number)."""
    by_number = {}
    lines = []
    for tc in controllers:
        n = int(tc.ToolNumber)
        line = table_line(n, *swarf_tool(tc))
        if n in by_number:
            if by_number[n][1] != line:
                raise SwarfError(
                    'tool controllers "%s" and "%s" both use T%d with '
                    "different tools" % (by_number[n][0], tc.Label, n))
            continue
        by_number[n] = (tc.Label, line)
        lines.append(line)
    return "".join(l + "\n" for l in lines)
