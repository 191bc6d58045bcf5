# simulate-job's code inside freecadcmd: the wrapper passes its arguments as
# JSON in $SWARF_FREECAD_ARGS (freecadcmd takes every other argument as a
# file to open). Exit: 0 done, 3 swarf's verdict (out of tolerance with
# --tolerance), 1 an error (named), 2 bad arguments.
import argparse
import json
import os
import sys

USAGE = "simulate-job JOB.FCStd --out DIR [options]"


def parser():
    p = argparse.ArgumentParser(
        prog="simulate-job", usage=USAGE,
        description="Simulates the FreeCAD CAM Job of JOB.FCStd on swarf "
        "(headless, under freecadcmd): posts it with FreeCAD's LinuxCNC post, "
        "writes its tools, stock and model, runs `swarf run` and writes the "
        "same files as `swarf run --out`, plus program.ngc, tools.tbl, "
        "design.stl, lines.json, command.txt and report.txt. Options not "
        "given come from the add-on's preferences.")
    p.add_argument("file", help="the FreeCAD document (.FCStd)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--job", help="the Job's name or label (when several)")
    p.add_argument("--swarf", help="the swarf CLI (default: preferences, "
                   "else swarf on PATH)")
    p.add_argument("--server", help="a running swarfd HOST:PORT")
    p.add_argument("--token", help="its bearer token (or $SWARF_TOKEN)")
    p.add_argument("--tls-ca", help="use TLS, trusting this PEM CA")
    p.add_argument("--tls-cert", help="client certificate (PEM)")
    p.add_argument("--tls-key", help="client key (PEM)")
    p.add_argument("--swarfd", help="start this swarfd locally for the run "
                   "(without --server)")
    p.add_argument("--embedded", action="store_true",
                   help="swarf's embedded server, whatever the preferences say")
    p.add_argument("--spacing", type=float, help="grid spacing (mm)")
    p.add_argument("--tolerance", type=float, help="tolerance (mm); given, "
                   "out of tolerance exits 3")
    p.add_argument("--allowance", type=float, help="stock to leave (mm)")
    p.add_argument("--no-design", action="store_true",
                   help="do not compare with the Job's model")
    p.add_argument("--deflection", type=float,
                   help="the model's tessellation: largest chord error "
                   "(mm, default 0.01)")
    p.add_argument("--color-by", choices=("deviation", "height"),
                   help="the Mesh's vertex colours (default: preferences, "
                   "else deviation)")
    p.add_argument("--recompute", action="store_true",
                   help="recompute the document before posting")
    p.add_argument("--save", metavar="FCSTD",
                   help="save the document with the surface Mesh here")
    p.add_argument("--swarf-arg", action="append", default=[],
                   metavar="ARG", help="an extra argument for swarf run "
                   "(repeatable), e.g. --swarf-arg=--check")
    return p


def options_from(args):
    from . import prefs
    o = prefs.options()
    if args.swarf:
        o.swarf = args.swarf
    if args.embedded:
        o.server, o.swarfd = "", ""
    if args.server:
        o.server = args.server
    if args.swarfd:
        o.swarfd = args.swarfd
        if not args.server:
            o.server = ""
    for name in ("token", "tls_ca", "tls_cert", "tls_key"):
        if getattr(args, name):
            setattr(o, name, getattr(args, name))
    if args.spacing is not None:
        o.spacing = args.spacing
    if args.tolerance is not None:
        o.tolerance = args.tolerance
    if args.allowance is not None:
        o.allowance = args.allowance
    if args.no_design:
        o.design = False
    if args.deflection is not None:
        o.deflection = args.deflection
    if args.color_by:
        o.color_by = args.color_by
    o.extra_args += args.swarf_arg
    # Paths given relative to where simulate-job was started.
    for name in ("swarf", "swarfd", "tls_ca", "tls_cert", "tls_key"):
        value = getattr(o, name)
        if value and os.sep in value:
            setattr(o, name, os.path.abspath(value))
    return o


def main():
    argv = json.loads(os.environ.get("SWARF_FREECAD_ARGS", "[]"))
    p = parser()
    try:
        args = p.parse_args(argv)
        for name in ("spacing", "deflection"):
            value = getattr(args, name)
            if value is not None and not value > 0:
                p.error("--%s must be > 0 (got %g)" % (name, value))
    except SystemExit as e:
        sys.exit(2 if e.code else 0)
    import FreeCAD
    from .compat import SwarfError
    from . import simulate
    from . import runner

    def err(text):
        sys.stderr.write(text)
        sys.stderr.flush()

    try:
        if not os.path.exists(args.file):
            raise SwarfError("%s: no such file" % args.file)
        doc = FreeCAD.openDocument(os.path.abspath(args.file))
        if args.recompute:
            doc.recompute()
        job = simulate.find_job(doc, args.job)
        result = simulate.simulate(job, args.out, options_from(args),
                                   echo=err, stage=lambda s: err(
                                       "simulate-job: %s\n" % s))
        mesh = result.mesh.Mesh
        err("simulate-job: surface mesh %s: %d triangles, %s\n" % (
            result.mesh.Label, mesh.CountFacets,
            "watertight" if mesh.isSolid() and not mesh.hasNonManifolds()
            else "NOT watertight"))
        if args.save:
            doc.saveAs(os.path.abspath(args.save))
        sys.stdout.write(result.report)
        sys.stdout.flush()
        sys.exit(3 if result.returncode == 3 else 0)
    except SwarfError as e:
        err("simulate-job: error: %s\n" % e)
        sys.exit(1)
    except runner.Cancelled:
        err("simulate-job: cancelled\n")
        sys.exit(1)
