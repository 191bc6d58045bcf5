# "Simulate with swarf" without the GUI: a Job posted, its tools, stock and
# model written beside the program, the swarf CLI run on them (it is the
# client: the files in the output folder are exactly those of
# `swarf run --out`), the machined surface added to the document as a Mesh,
# and a report naming the operation and command behind every line it cites.
#
# Files written to the output folder besides swarf's own:
#   program.ngc  the posted G-code (FreeCAD's LinuxCNC post)
#   tools.tbl    the tool table (tools.py)
#   design.stl   the Job's model, tessellated (when there is one)
#   lines.json   posted line -> [operation, command index, command]
#   command.txt  the swarf command line that ran
#   report.txt   the report (report.py)
import json
import os
import shlex
import shutil

from . import post as post_mod
from . import report as report_mod
from . import runner
from . import tools as tools_mod
from .compat import SwarfError


class Options:
    """How to run swarf. Paths are executables; server is HOST:PORT."""

    def __init__(self, swarf="swarf", server="", token="", tls_ca="",
                 tls_cert="", tls_key="", swarfd="", spacing=None,
                 design=True, tolerance=None, allowance=None,
                 deflection=0.01, extra_args=(), color_by="deviation"):
        self.swarf = swarf
        self.server = server
        self.token = token
        self.tls_ca = tls_ca
        self.tls_cert = tls_cert
        self.tls_key = tls_key
        self.swarfd = swarfd
        self.spacing = spacing
        self.design = design
        self.tolerance = tolerance
        self.allowance = allowance
        self.deflection = deflection
        self.extra_args = list(extra_args)
        self.color_by = color_by  # "deviation" or "height"


class Result:
    def __init__(self, job, out_dir, returncode, output, stats, lines,
                 report, mesh_obj):
        self.job = job
        self.out_dir = out_dir
        self.returncode = returncode  # swarf's: 0, or 3 out of tolerance
        self.output = output  # swarf's terminal output
        self.stats = stats  # stats.json
        self.lines = lines  # {line: (operation, index, command)}
        self.report = report  # the report's text
        self.mesh = mesh_obj  # the Mesh::Feature in the document


def _num(x):
    return repr(float(x))


def stock_arg(job):
    """--stock x0,y0,x1,y1,top from the Job's stock's bounding box (a
    cylinder or rotated stock is simulated as that box)."""
    stock = getattr(job, "Stock", None)
    if stock is None or not hasattr(stock, "Shape") or stock.Shape.isNull():
        raise SwarfError('Job "%s" has no stock' % job.Label)
    bb = stock.Shape.BoundBox
    return ",".join(_num(v) for v in (bb.XMin, bb.YMin, bb.XMax, bb.YMax, bb.ZMax))


def model_shape(job):
    """The Job's models (its Model group: clones placed where the Job cuts
    them) as one shape, or None."""
    import Part
    shapes = [o.Shape for o in getattr(job.Model, "Group", [])
              if hasattr(o, "Shape") and not o.Shape.isNull()]
    if not shapes:
        return None
    return shapes[0] if len(shapes) == 1 else Part.makeCompound(shapes)


def write_design(job, path, deflection):
    """Tessellates the Job's model into a binary STL at `path`; False
    where the Job has no model."""
    import MeshPart
    shape = model_shape(job)
    if shape is None:
        return False
    mesh = MeshPart.meshFromShape(Shape=shape, LinearDeflection=deflection,
                                  AngularDeflection=0.1, Relative=False)
    if mesh.CountFacets == 0:
        raise SwarfError('Job "%s": its model tessellates to no triangles'
                         % job.Label)
    mesh.write(path)
    return True


def command(options, program, table, stock, design, out_dir, server):
    cmd = [options.swarf, "run", program, "--tools", table, "--stock", stock,
           "--out", out_dir]
    if design:
        cmd += ["--design", design]
        if options.tolerance is not None:
            cmd += ["--tolerance", _num(options.tolerance)]
        if options.allowance is not None:
            cmd += ["--allowance", _num(options.allowance)]
    if options.spacing:
        cmd += ["--spacing", _num(options.spacing)]
    if server:
        cmd += ["--server", server]
        if options.tls_ca:
            cmd += ["--tls-ca", options.tls_ca]
        if options.tls_cert:
            cmd += ["--tls-cert", options.tls_cert, "--tls-key", options.tls_key]
    cmd += options.extra_args
    return cmd


def find_job(doc, name=None):
    from . import compat
    jobs = compat.jobs(doc)
    if name:
        jobs = [j for j in jobs if name in (j.Name, j.Label)]
        if not jobs:
            raise SwarfError('no Job named "%s" in %s' % (name, doc.Name))
    if not jobs:
        raise SwarfError("the document %s has no CAM Job" % doc.Name)
    if len(jobs) > 1:
        raise SwarfError("the document %s has %d Jobs (%s): name one" % (
            doc.Name, len(jobs), ", ".join(j.Label for j in jobs)))
    return jobs[0]


def prepare(job, out_dir, options):
    """Posts the Job and writes program.ngc, tools.tbl, design.stl and
    lines.json into out_dir. Returns (cmd without server, files dict,
    line map)."""
    os.makedirs(out_dir, exist_ok=True)
    text, objs = post_mod.post(job)
    program = os.path.join(out_dir, "program.ngc")
    with open(program, "w") as f:
        f.write(text)
    controllers = [o for o in objs if post_mod.is_tool_controller(o)]
    if not controllers:
        raise SwarfError('Job "%s": no tool controller is posted' % job.Label)
    table = os.path.join(out_dir, "tools.tbl")
    with open(table, "w") as f:
        f.write(tools_mod.tool_table(controllers))
    design = None
    if options.design:
        design = os.path.join(out_dir, "design.stl")
        if not write_design(job, design, options.deflection):
            design = None
    lines = post_mod.line_map(text, objs)
    with open(os.path.join(out_dir, "lines.json"), "w") as f:
        json.dump({str(k): list(v) for k, v in sorted(lines.items())}, f,
                  indent=0)
    return program, table, design, lines


# Deviation colouring casts a ray per vertex (about 65 us each on 0.20, five
# where it finds a gouge); bigger meshes are coloured by height.
MAX_DEVIATION_POINTS = 200000


def color_mesh(obj, out_dir, stats, color_by):
    """Sets obj.VertexColors by deviation (when a design was compared) or
    height; returns which."""
    import Mesh
    from . import colors
    points = obj.Mesh.Points
    design = os.path.join(out_dir, "design.stl")
    dev = stats.get("deviation")
    how = "height"
    if (color_by == "deviation" and dev and os.path.exists(design) and
            len(points) <= MAX_DEVIATION_POINTS):
        st = stats["stock"]
        spacing = (st["x1"] - st["x0"]) / st["nx"]
        tolerance = dev.get("tolerance", 0.01)
        values = colors.deviation_values(points, Mesh.Mesh(design), spacing,
                                         tolerance)
        cols = colors.deviation_colors(values, tolerance,
                                       dev.get("allowance", 0.0))
        how = "deviation"
    else:
        cols = colors.height_colors(points)
    if "VertexColors" not in obj.PropertiesList:
        obj.addProperty("App::PropertyColorList", "VertexColors", "swarf",
                        "Per-vertex colours (by %s)" % how)
    obj.VertexColors = cols
    return how


def add_mesh(doc, job, out_dir, stats, color_by="deviation"):
    """The surface mesh (out_dir/surface.stl) in the document, coloured,
    replacing this Job's previous one."""
    import Mesh
    for o in list(doc.Objects):
        if getattr(o, "SwarfJob", None) == job.Name:
            doc.removeObject(o.Name)
    obj = doc.addObject("Mesh::Feature", "SwarfSurface")
    obj.Mesh = Mesh.Mesh(os.path.join(out_dir, "surface.stl"))
    obj.Label = "swarf: %s" % job.Label
    obj.addProperty("App::PropertyString", "SwarfJob", "swarf",
                    "The Job this surface simulates")
    obj.SwarfJob = job.Name
    obj.addProperty("App::PropertyPath", "SwarfOutput", "swarf",
                    "swarf's output folder")
    obj.SwarfOutput = out_dir
    obj.addProperty("App::PropertyString", "SwarfColoring", "swarf",
                    "What the vertex colours show")
    obj.SwarfColoring = color_mesh(obj, out_dir, stats, color_by)
    doc.recompute()
    return obj


def simulate(job, out_dir, options, progress=None, cancelled=None,
             idle=None, echo=None, use_pty=False, stage=None):
    """Simulates `job`; returns a Result. SwarfError for anything the user
    must fix (naming it), runner.Cancelled when cancelled() turned True."""
    def say(text):
        if stage:
            stage(text)
    out_dir = os.path.abspath(out_dir)
    say("posting %s" % job.Label)
    program, table, design, lines = prepare(job, out_dir, options)
    stats_path = os.path.join(out_dir, "stats.json")
    if os.path.exists(stats_path):
        os.remove(stats_path)  # never report an older run's figures
    swarf = options.swarf
    if os.sep not in swarf and shutil.which(swarf) is None:
        raise SwarfError("the swarf CLI %r is not on PATH: set its path in "
                         "the add-on's preferences (or --swarf)" % swarf)
    server = options.server
    local = None
    env = dict(os.environ)
    if options.token:
        env["SWARF_TOKEN"] = options.token  # not on the command line
    try:
        if not server and options.swarfd:
            say("starting swarfd")
            local = runner.LocalServer(options.swarfd)
            server = local.address
        cmd = command(options, program, table, stock_arg(job), design,
                      out_dir, server)
        with open(os.path.join(out_dir, "command.txt"), "w") as f:
            f.write(" ".join(shlex.quote(c) for c in cmd) + "\n")
        say("simulating on %s" % (server or "swarf's embedded server"))
        try:
            rc, output = runner.run(cmd, env=env, progress=progress,
                                    cancelled=cancelled, idle=idle,
                                    echo=echo, use_pty=use_pty)
        except OSError as e:
            raise SwarfError("cannot run the swarf CLI %r: %s" % (swarf, e))
    finally:
        if local:
            local.stop()
    if rc not in (0, 3) or not os.path.exists(stats_path):
        tail = "\n".join(output.strip().splitlines()[-15:])
        raise SwarfError("swarf run failed (exit %d):\n%s" % (rc, tail))
    with open(stats_path) as f:
        stats = json.load(f)
    text = report_mod.report(job.Label, stats, lines, rc)
    with open(os.path.join(out_dir, "report.txt"), "w") as f:
        f.write(text)
    say("adding the surface to the document")
    mesh_obj = add_mesh(job.Document, job, out_dir, stats, options.color_by)
    return Result(job, out_dir, rc, output, stats, lines, text, mesh_obj)
