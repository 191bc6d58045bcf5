# Builds the FreeCAD documents the add-on's tests simulate, under freecadcmd
# (FreeCAD 0.20's Path scripting API, headless), into $SWARF_TEST_DIR:
#   job.FCStd       a 40 x 30 x 12 mm block with a 16 x 10 x 4 mm pocket and
#                   a 5 mm hole 6 mm deep; a Job (stock 1 mm around it) with
#                   a facing pass and the pocket (5 mm end mill, T1), the
#                   outside profile (6 mm bull nose, flat radius 1.5, T2) and
#                   the hole drilled (5 mm drill, 119 degrees, T3)
#   bad.FCStd       the same Job with T3 a slitting saw (no swarf tool)
#   ref/program.ngc the Job posted here with FreeCAD's own Post command's
#                   list and LinuxCNC post (not through the add-on)
#   ref/facts.json  what the test knows independently of the add-on
#
# Headless workaround (0.20): creating an operation in a Job with several
# tool controllers asks the GUI which one to use (PathUtils.UserInput); with
# no GUI, PathUtils.findToolController fails with UnboundLocalError. Setting
# PathUtils.UserInput to an object answering selectedToolController() picks
# the controller without a dialog.
import json
import os


def main():
    import FreeCAD
    import Part
    from PathScripts import (PathDrilling, PathJob, PathMillFace, PathPost,
                             PathPocketShape, PathProfile, PathToolBit,
                             PathToolController, PathUtils)
    from PathScripts.post import linuxcnc_post

    out = os.environ["SWARF_TEST_DIR"]
    os.makedirs(os.path.join(out, "ref"), exist_ok=True)
    bits = os.path.join(FreeCAD.getResourceDir(), "Mod", "Path", "Tools", "Bit")

    def build(bad):
        doc = FreeCAD.newDocument("bad" if bad else "job")
        block = Part.makeBox(40, 30, 12)
        pocket = Part.makeBox(16, 10, 4, FreeCAD.Vector(6, 10, 8))
        hole = Part.makeCylinder(2.5, 6, FreeCAD.Vector(32, 15, 6))
        part = doc.addObject("Part::Feature", "Part")
        part.Shape = block.cut(pocket).cut(hole)
        doc.recompute()
        job = PathJob.Create("Job", [part])
        # The Job's default tool controller goes: the test's three replace it.
        for tc in list(job.Tools.Group):
            doc.removeObject(tc.Tool.Name)
            doc.removeObject(tc.Name)

        def controller(fctb, number, label):
            bit = PathToolBit.Factory.CreateFrom(os.path.join(bits, fctb),
                                                 "Bit%d" % number)
            tc = PathToolController.Create("TC%d" % number, bit, number)
            tc.Label = label
            tc.HorizFeed = "600 mm/min"
            tc.VertFeed = "200 mm/min"
            tc.SpindleSpeed = 10000
            job.Proxy.addToolController(tc)
            return tc

        t1 = controller("5mm_Endmill.fctb", 1, "TC: Endmill")
        t2 = controller("6mm_Bullnose.fctb", 2, "TC: Bullnose")
        t3 = controller("slittingsaw.fctb" if bad else "5mm_Drill.fctb", 3,
                        "TC: Drill")

        class Headless:  # see the workaround above
            def selectedToolController(self):
                return t1

        PathUtils.UserInput = Headless()
        model = job.Model.Group[0]
        top = [i + 1 for i, f in enumerate(model.Shape.Faces)
               if f.Surface.__class__.__name__ == "Plane" and
               abs(f.CenterOfMass.z - 12) < 1e-9 and f.normalAt(0, 0).z > 0.5]
        floor = [i + 1 for i, f in enumerate(model.Shape.Faces)
                 if abs(f.CenterOfMass.z - 8) < 1e-9 and
                 f.normalAt(0, 0).z > 0.5]
        wall = [i + 1 for i, f in enumerate(model.Shape.Faces)
                if f.Surface.__class__.__name__ == "Cylinder"]
        face = PathMillFace.Create("Facing")
        face.Base = [(model, ["Face%d" % top[0]])]
        face.ToolController = t1
        face.StepOver = 50
        pocket_op = PathPocketShape.Create("Pocket")
        pocket_op.Base = [(model, ["Face%d" % floor[0]])]
        pocket_op.ToolController = t1
        pocket_op.StepOver = 50
        profile = PathProfile.Create("Profile")
        profile.ToolController = t2
        drill = PathDrilling.Create("Drilling")
        drill.Base = [(model, ["Face%d" % wall[0]])]
        drill.ToolController = t3
        doc.recompute()
        return doc, job

    doc, job = build(False)
    doc.saveAs(os.path.join(out, "job.FCStd"))
    # Posted from the saved file, as simulate-job reads it (a reload can
    # turn a 0 into -0 in a Path command).
    FreeCAD.closeDocument(doc.Name)
    doc = FreeCAD.openDocument(os.path.join(out, "job.FCStd"))
    job = doc.getObject("Job")
    objs = [o for sub in PathPost.CommandPathPost().buildPostList(job)
            for o in sub]
    gcode = linuxcnc_post.export(objs, "-", "--no-show-editor")
    with open(os.path.join(out, "ref", "program.ngc"), "w") as f:
        f.write(gcode)
    facts = {
        "ops": {op.Label: len(op.Path.Commands) for op in job.Operations.Group},
        "stock": [job.Stock.Shape.BoundBox.XMin, job.Stock.Shape.BoundBox.YMin,
                  job.Stock.Shape.BoundBox.XMax, job.Stock.Shape.BoundBox.YMax,
                  job.Stock.Shape.BoundBox.ZMax],
        "model_volume": job.Model.Group[0].Shape.Volume,
    }
    with open(os.path.join(out, "ref", "facts.json"), "w") as f:
        json.dump(facts, f)
    FreeCAD.closeDocument(doc.Name)
    bad, _ = build(True)
    bad.saveAs(os.path.join(out, "bad.FCStd"))


main()
