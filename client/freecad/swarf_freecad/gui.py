# The GUI: the "Simulate with swarf" command for the active Job (in the
# Path workbench of 0.20, the CAM workbench of 1.0), its progress dialog
# (cancel kills swarf), the report in the report view, the surface Mesh
# coloured, and the preferences page.
import os
import tempfile

import FreeCAD
import FreeCADGui

from . import compat
from . import prefs
from . import runner
from . import simulate
from .compat import SwarfError

COMMAND = "Swarf_Simulate"
ICON = os.path.join(os.path.dirname(os.path.dirname(__file__)), "Resources",
                    "swarf.svg")
WORKBENCHES = ("PathWorkbench", "CAMWorkbench")


def _qt():
    from PySide import QtCore, QtGui
    return QtCore, QtGui


def active_job():
    """The selected Job (or the Job of a selected operation), else the
    document's only Job."""
    doc = FreeCAD.ActiveDocument
    if doc is None:
        raise SwarfError("no document is open")
    for sel in FreeCADGui.Selection.getSelection():
        obj = sel
        while obj is not None:
            if compat.is_job(obj):
                return obj
            parents = [p for p in obj.InList if p is not obj]
            obj = parents[0] if parents else None
    return simulate.find_job(doc)


def output_dir(job):
    base = prefs.get("OutputDir")
    if not base:
        doc_file = job.Document.FileName
        base = (os.path.join(os.path.dirname(doc_file), "swarf")
                if doc_file else os.path.join(tempfile.gettempdir(), "swarf"))
    return os.path.join(base, "%s-%s" % (job.Document.Name, job.Name))


class SimulateCommand:
    def GetResources(self):
        return {"Pixmap": ICON if os.path.exists(ICON) else "",
                "MenuText": "Simulate with swarf",
                "ToolTip": "Simulate the active Job on swarf: the machined "
                "surface as a mesh, its deviation from the model and the "
                "safety report"}

    def IsActive(self):
        return bool(compat.jobs(FreeCAD.ActiveDocument))

    def Activated(self):
        QtCore, QtGui = _qt()
        try:
            job = active_job()
        except SwarfError as e:
            FreeCAD.Console.PrintError("swarf: %s\n" % e)
            QtGui.QMessageBox.warning(None, "Simulate with swarf", str(e))
            return
        dialog = QtGui.QProgressDialog("Posting %s..." % job.Label, "Cancel",
                                       0, 100, FreeCADGui.getMainWindow())
        dialog.setWindowTitle("Simulate with swarf")
        dialog.setWindowModality(QtCore.Qt.WindowModal)
        dialog.setMinimumDuration(0)
        dialog.setValue(0)
        app = QtGui.QApplication.instance()

        def stage(text):
            dialog.setLabelText(text)
            app.processEvents()

        def progress(pct):
            dialog.setValue(min(pct, 99))

        out = output_dir(job)
        try:
            result = simulate.simulate(
                job, out, prefs.options(), progress=progress,
                cancelled=dialog.wasCanceled, idle=app.processEvents,
                echo=FreeCAD.Console.PrintLog, use_pty=os.name == "posix",
                stage=stage)
        except runner.Cancelled:
            dialog.close()
            FreeCAD.Console.PrintWarning("swarf: cancelled\n")
            return
        except SwarfError as e:
            dialog.close()
            FreeCAD.Console.PrintError("swarf: %s\n" % e)
            QtGui.QMessageBox.critical(None, "Simulate with swarf", str(e))
            return
        except Exception:  # FreeCAD's own, while posting: never leave the
            dialog.close()  # modal dialog up
            import traceback
            FreeCAD.Console.PrintError("swarf: %s" % traceback.format_exc())
            QtGui.QMessageBox.critical(
                None, "Simulate with swarf",
                "Simulating %s failed; the report view has the details."
                % job.Label)
            return
        dialog.setValue(100)
        dialog.close()
        vo = getattr(result.mesh, "ViewObject", None)
        if vo is not None and hasattr(vo, "Coloring"):
            vo.Coloring = True
        # The surface is hidden under the Job's stock and model: hide them
        # (the Job's own objects, not the user's bodies).
        stock = getattr(job, "Stock", None)
        for obj in [stock] + list(getattr(job.Model, "Group", [])):
            if obj is not None and getattr(obj, "ViewObject", None):
                obj.ViewObject.Visibility = False
        report = result.report + "swarf's files: %s\n" % out
        if result.stats.get("deviation", {}).get("ok") is False or \
                not result.stats.get("safety", {}).get("ok", True):
            FreeCAD.Console.PrintWarning(report)
        else:
            FreeCAD.Console.PrintMessage(report)
        FreeCADGui.SendMsgToActiveView("ViewFit")


class PreferencesPage:
    """Edit > Preferences > swarf: the fields of prefs.FIELDS."""

    def __init__(self, parent=None):
        QtCore, QtGui = _qt()
        self.form = QtGui.QWidget(parent)
        self.form.setWindowTitle("swarf")
        layout = QtGui.QFormLayout(self.form)
        self.widgets = {}
        for name, kind, default, text in prefs.FIELDS:
            if kind == "bool":
                w = QtGui.QCheckBox()
            elif kind == "float":
                w = QtGui.QDoubleSpinBox()
                w.setDecimals(4)
                w.setRange(0, 1000)
            elif name == "ColorBy":
                w = QtGui.QComboBox()
                w.addItems(["deviation", "height"])
            else:
                w = QtGui.QLineEdit()
                if name == "Token":
                    w.setEchoMode(QtGui.QLineEdit.Password)
            layout.addRow(text, w)
            self.widgets[name] = (kind, w)

    def loadSettings(self):
        for name, (kind, w) in self.widgets.items():
            v = prefs.get(name)
            if kind == "bool":
                w.setChecked(v)
            elif kind == "float":
                w.setValue(v)
            elif hasattr(w, "setCurrentIndex"):
                w.setCurrentIndex(max(0, w.findText(v)))
            else:
                w.setText(v)

    def saveSettings(self):
        for name, (kind, w) in self.widgets.items():
            if kind == "bool":
                prefs.set(name, w.isChecked())
            elif kind == "float":
                prefs.set(name, w.value())
            elif hasattr(w, "currentText"):
                prefs.set(name, w.currentText())
            else:
                prefs.set(name, w.text())


_toolbar = None


def _on_workbench(name):
    """Shows a "swarf" toolbar with the command in the Path/CAM workbench
    (0.20 has no workbench manipulators to add it to the workbench's own)."""
    global _toolbar
    QtCore, QtGui = _qt()
    mw = FreeCADGui.getMainWindow()
    if _toolbar is None and name in WORKBENCHES:
        _toolbar = QtGui.QToolBar("swarf", mw)
        _toolbar.setObjectName("swarf")
        action = _toolbar.addAction("Simulate with swarf")
        if os.path.exists(ICON):
            action.setIcon(QtGui.QIcon(ICON))
        action.setToolTip(SimulateCommand().GetResources()["ToolTip"])
        action.triggered.connect(lambda: FreeCADGui.runCommand(COMMAND))
        mw.addToolBar(_toolbar)
    if _toolbar is not None:
        _toolbar.setVisible(name in WORKBENCHES)


def register():
    FreeCADGui.addCommand(COMMAND, SimulateCommand())
    FreeCADGui.addPreferencePage(PreferencesPage, "swarf")
    mw = FreeCADGui.getMainWindow()
    mw.workbenchActivated.connect(_on_workbench)
