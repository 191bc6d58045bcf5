# Posting a Job with FreeCAD's own LinuxCNC post processor (canned cycles,
# arcs and tool changes come out as FreeCAD writes them for a real machine),
# and the map from posted line numbers back to the operation and the Path
# command that made each line.
import contextlib
import io
import shlex

from . import compat
from .compat import SwarfError


def _active(obj):
    if hasattr(obj, "Active") and not obj.Active:
        return False
    base = getattr(obj, "Base", None)
    if hasattr(base, "Active") and not base.Active:
        return False
    return True


class _Fixture:
    """A work offset as FreeCAD's Post command posts it: G54.. then a rapid
    to the clearance height above the stock."""

    def __init__(self, job, name):
        import Path
        self.Label = name
        self.Name = name
        z = job.Stock.Shape.BoundBox.ZMax + job.SetupSheet.ClearanceHeightOffset.Value
        self.Path = Path.Path([Path.Command(name), Path.Command("G0 Z%s" % z)])


def _own_post_list(job):
    """FreeCAD's default order (OrderOutputBy "Fixture") where FreeCAD's
    buildPostList could not be used: per fixture, every active operation,
    its tool controller first where the tool changes."""
    out = []
    for f in job.Fixtures:
        out.append(_Fixture(job, f))
        current = None
        for op in job.Operations.Group:
            if not _active(op):
                continue
            tc = getattr(op, "ToolController", None)
            if tc is not None and tc is not current:
                out.append(tc)
                current = tc
            out.append(op)
    return out


def post_list(job):
    objs = compat.freecad_post_list(job)
    return objs if objs is not None else _own_post_list(job)


def post_args(job):
    """The Job's own LinuxCNC arguments (when its post is linuxcnc), never
    opening the editor."""
    args = ""
    if (getattr(job, "PostProcessor", "") or "") == "linuxcnc":
        args = getattr(job, "PostProcessorArgs", "") or ""
    words = shlex.split(args)
    if "--no-show-editor" not in words:
        words.append("--no-show-editor")
    return " ".join(shlex.quote(w) for w in words)


def is_tool_controller(obj):
    return hasattr(obj, "ToolNumber") and hasattr(obj, "Tool")


def post(job):
    """(G-code text, objects posted in order)."""
    objs = post_list(job)
    if not any(hasattr(o, "Path") and not is_tool_controller(o) and
               getattr(o, "Path", None) and o.Path.Commands for o in objs):
        raise SwarfError('Job "%s" has no active operation with a path '
                         "(recompute the document?)" % job.Label)
    post_mod = compat.linuxcnc_post()
    # The post prints its progress ("postprocessing...") with print().
    with contextlib.redirect_stdout(io.StringIO()):
        text = post_mod.export(objs, "-", post_args(job))
    if not text:
        raise SwarfError("FreeCAD's LinuxCNC post processor wrote nothing for "
                         'Job "%s" (arguments: %s)' % (job.Label, post_args(job)))
    return text, objs


def _body(line):
    """The line without a line number the post may prefix (--line-numbers)."""
    body = line.strip()
    first = body.split(None, 1)
    if first and first[0][:1] in "Nn" and first[0][1:].isdigit():
        body = first[1] if len(first) > 1 else ""
    return body


def _matches(line, command_name):
    body = _body(line)
    if command_name.startswith("("):
        return body.startswith(command_name)
    return bool(body) and body.split(None, 1)[0] == command_name


# A command's line is at most this far after the previous one (the post adds
# M5 before an M6); further means the post left the command out (--modal).
_WINDOW = 8


_ORDER = "XYZABCIJKRQPLFSTHD"


def describe(command):
    """A Path command as a user reads it: its name and parameters in mm
    (4 decimals at most), F in mm/min (FreeCAD keeps mm/s)."""
    if command.Name.startswith("("):
        return command.Name
    words = [command.Name]
    params = command.Parameters
    def order(k):  # the post's order; unknown words last
        return (_ORDER.index(k) if k in _ORDER else len(_ORDER), k)
    for k in sorted(params, key=order):
        v = params[k] * 60 if k == "F" else params[k]
        text = ("%.4f" % v).rstrip("0").rstrip(".")
        words.append(k + ("0" if text in ("-0", "") else text))
    return " ".join(words)


def line_map(text, objects):
    """{line number (1-based): (object label, command index, the Path
    command as describe() writes it)} for every posted line that a Path
    command made. Lines
    are matched in order by their command word inside each object's
    "(begin operation: LABEL)" block, so extra lines the post adds (M5 before
    M6, G43 after it, coolant, preamble) stay unmapped; where comments are
    off the whole text is one block."""
    lines = text.splitlines()
    result = {}
    cursor = 0
    for obj in objects:
        path = getattr(obj, "Path", None)
        if path is None:
            continue
        label = obj.Label
        begin = "(begin operation: %s)" % label
        end_at = len(lines)
        for i in range(cursor, len(lines)):
            if _body(lines[i]) == begin:
                cursor = i + 1
                for j in range(cursor, len(lines)):
                    if "(finish operation: %s)" % label in lines[j]:
                        end_at = j
                        break
                break
        for index, c in enumerate(path.Commands):
            name = c.Name
            for i in range(cursor, min(end_at, cursor + _WINDOW)):
                if _matches(lines[i], name):
                    result[i + 1] = (label, index, describe(c))
                    cursor = i + 1
                    break
        cursor = max(cursor, min(end_at, len(lines)))
    return result
