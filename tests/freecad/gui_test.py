#!/usr/bin/env python3
# The add-on in FreeCAD's GUI (under Xvfb), installed as a user installs it
# (a link in the Mod folder of a scratch $HOME): the "Simulate with swarf"
# toolbar in the Path workbench only, the command cancelled mid-run (its
# progress dialog's Cancel; the swarf process is killed), then run: the
# coloured Mesh in the document and the report in the report view.
#
#   gui_test.py --swarf PATH [--work DIR]
#
# Exits 77 (skipped) without freecad/freecadcmd or xvfb-run.
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))

# Runs inside FreeCAD's GUI; %(name)s are filled in below.
GUI_SCRIPT = r'''
import json, os, traceback
res = {"dialogs": []}
try:
    import FreeCAD, FreeCADGui
    from PySide import QtCore, QtGui
    # 0.20's Path workbench warns in a dialog on activation unless the unit
    # schema gives velocities per minute: choose "Metric, Small Parts & CNC".
    FreeCAD.ParamGet("User parameter:BaseApp/Preferences/Units").SetInt(
        "UserSchema", 6)
    FreeCAD.Units.setSchema(6)

    def watch():
        """Cancels the progress dialog once swarf reported progress; notes
        and closes any other dialog (an error box would hang the test)."""
        w = QtGui.QApplication.activeModalWidget()
        if isinstance(w, QtGui.QProgressDialog):
            if res.get("cancel") and w.value() >= 25:
                w.cancel()
        elif w is not None:
            res["dialogs"].append([w.windowTitle()] + [
                l.text() for l in w.findChildren(QtGui.QLabel)])
            w.reject() if hasattr(w, "reject") else w.close()
    timer = QtCore.QTimer()
    timer.timeout.connect(watch)
    timer.start(100)

    from swarf_freecad import prefs
    prefs.set("Spacing", 0.25)
    prefs.set("OutputDir", %(out)r)
    mw = FreeCADGui.getMainWindow()
    doc = FreeCAD.openDocument(%(job)r)
    FreeCADGui.activateWorkbench("PathWorkbench")
    tb = mw.findChild(QtGui.QToolBar, "swarf")
    res["toolbar"] = tb is not None and tb.isVisible()
    res["action"] = [a.text() for a in tb.actions()] if tb else []
    FreeCADGui.Selection.addSelection(doc.getObject("Job"))

    res["cancel"] = True
    prefs.set("SwarfPath", %(slow)r)
    FreeCADGui.runCommand("Swarf_Simulate")
    res["meshes_after_cancel"] = len(
        [o for o in doc.Objects if o.TypeId == "Mesh::Feature"])
    res["cancel"] = False

    prefs.set("SwarfPath", %(swarf)r)
    FreeCADGui.runCommand("Swarf_Simulate")
    meshes = [o for o in doc.Objects if o.TypeId == "Mesh::Feature"]
    res["meshes"] = len(meshes)
    m = meshes[0]
    res["coloring"] = m.ViewObject.Coloring
    res["colors"] = len(m.VertexColors)
    res["points"] = m.Mesh.CountPoints
    res["solid"] = m.Mesh.isSolid()
    res["stock_hidden"] = not doc.getObject("Job").Stock.ViewObject.Visibility
    for _ in range(20):  # the report view gets messages as queued events
        QtGui.QApplication.processEvents()
    rv = mw.findChild(QtGui.QTextEdit, "Report view")
    res["report"] = rv.toPlainText() if rv else ""
    FreeCADGui.activateWorkbench("PartWorkbench")
    res["toolbar_elsewhere"] = tb.isVisible()
    # The preferences page: shows what is stored, stores what is edited.
    from swarf_freecad import gui
    page = gui.PreferencesPage()
    page.loadSettings()
    kind, w = page.widgets["Spacing"]
    res["page_spacing"] = w.value()
    w.setValue(0.5)
    page.widgets["Server"][1].setText("example:1234")
    page.saveSettings()
    res["saved"] = [prefs.get("Spacing"), prefs.get("Server"),
                    prefs.get("SwarfPath")]
except Exception:
    res["error"] = traceback.format_exc()
with open(%(result)r, "w") as f:
    json.dump(res, f, indent=1)
os._exit(0)
'''


def running(pid):
    """Alive and not a zombie waiting to be reaped, 5 s after a SIGKILL
    (asynchronous) at the latest."""
    for _ in range(100):
        try:
            with open("/proc/%d/stat" % pid) as f:
                if f.read().rsplit(")", 1)[1].split()[0] == "Z":
                    return False
        except FileNotFoundError:
            return False
        time.sleep(0.05)
    return True


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--swarf", required=True)
    p.add_argument("--work")
    args = p.parse_args()
    missing = [t for t in ("freecad", "freecadcmd", "xvfb-run")
               if shutil.which(t) is None]
    if missing:
        print("SKIP: %s not installed (make test-freecad installs them)"
              % ", ".join(missing))
        return 77
    work = args.work or tempfile.mkdtemp(prefix="swarf-freecad-gui-")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    env = dict(os.environ, SWARF_TEST_DIR=work)
    subprocess.run(["freecadcmd", "-c", "exec(open(%r).read())" %
                    os.path.join(HERE, "make_job.py")], env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   timeout=120)
    home = os.path.join(work, "home")
    mod = os.path.join(home, ".local", "share", "FreeCAD", "Mod")
    os.makedirs(mod)
    os.symlink(os.path.join(ROOT, "client", "freecad"),
               os.path.join(mod, "swarf"))
    slow = os.path.join(work, "slow-swarf")
    pids = os.path.join(work, "slow.pids")
    with open(slow, "w") as f:
        f.write("#!/bin/sh\nsleep 60 &\necho $! > %s\n"
                "echo 'swarf: 25%% (1 of 4 moves, 0.00M moves/s)'\nwait\n"
                % pids)
    os.chmod(slow, 0o755)
    result = os.path.join(work, "result.json")
    script = os.path.join(work, "gui_script.py")
    with open(script, "w") as f:
        f.write(GUI_SCRIPT % {
            "out": os.path.join(work, "out"),
            "job": os.path.join(work, "job.FCStd"),
            "swarf": os.path.abspath(args.swarf), "slow": slow,
            "result": result})
    env = dict(os.environ, HOME=home,
               # FreeCAD's Qt WebEngine refuses to start as root otherwise.
               QTWEBENGINE_CHROMIUM_FLAGS="--no-sandbox")
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24",
                        "freecad", script], env=env, stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, timeout=150)
    if not os.path.exists(result):
        print(r.stdout.decode()[-3000:])
        print("FAIL: the GUI script wrote no result")
        return 1
    with open(result) as f:
        res = json.load(f)
    failures = []

    def check(ok, what):
        print("%s: %s" % ("ok" if ok else "FAIL", what))
        if not ok:
            failures.append(what)

    check("error" not in res, "no exception: %s" % res.get("error"))
    check(res.get("dialogs") == [], "no dialog: %s" % res.get("dialogs"))
    check(res.get("toolbar") is True, "the swarf toolbar shows in Path")
    check(res.get("action") == ["Simulate with swarf"], "its action")
    check(res.get("toolbar_elsewhere") is False, "hidden in Part")
    check(res.get("page_spacing") == 0.25, "the preferences page shows 0.25")
    check(res.get("saved") == [0.5, "example:1234",
                               os.path.abspath(args.swarf)],
          "the preferences page saves: %s" % res.get("saved"))
    check(res.get("meshes_after_cancel") == 0, "cancel adds no mesh")
    with open(pids) as f:
        pid = int(f.read())
    check(not running(pid), "cancel killed swarf's process group (pid %d)" % pid)
    report = res.get("report", "")
    check("swarf: cancelled" in report, "the report view says cancelled")
    check(res.get("meshes") == 1, "one surface mesh")
    check(res.get("coloring") is True, "its colours shown")
    check(res.get("colors") == res.get("points"), "a colour per vertex")
    check(res.get("solid") is True, "watertight")
    check(res.get("stock_hidden") is True, "the Job's stock hidden")
    check("verdict: OUT OF TOLERANCE" in report, "the verdict in the report")
    check("(Pocket, command" in report, "lines named by operation")
    check("swarf's files: %s" % os.path.join(work, "out") in report,
          "the output folder named")
    if failures:
        print(report[-3000:])
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
