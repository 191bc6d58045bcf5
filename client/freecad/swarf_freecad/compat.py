# The parts of FreeCAD's Path/CAM workbench the add-on uses, found where each
# version keeps them: FreeCAD 0.20 names the workbench "Path" and keeps its
# Python in PathScripts; 0.21 and 1.0 (where it is "CAM") moved it into the
# Path package (Path.Main.Job, Path.Post.Command, Path.Post.scripts). Nothing
# here imports FreeCADGui, so it all runs under freecadcmd. Only 0.20 was
# tried (README, "FreeCAD CAM add-on"); the later locations are from
# FreeCAD's sources.
import importlib


class SwarfError(Exception):
    """An error the user can act on; the message names the object or file."""


def linuxcnc_post():
    """FreeCAD's LinuxCNC post processor module, freshly loaded: the post keeps
    its settings (and line counter) in module globals, so every posting starts
    from a reload, as FreeCAD's own PostProcessor.load does."""
    errors = []
    for name in (
            "PathScripts.post.linuxcnc_post",  # 0.20
            "Path.Post.scripts.linuxcnc_post",  # 0.21, 1.0
            # Later versions turned linuxcnc_post into a class and kept the
            # export() script under this name.
            "Path.Post.scripts.linuxcnc_legacy_post"):
        try:
            mod = importlib.import_module(name)
        except ImportError as e:
            errors.append("%s (%s)" % (name, e))
            continue
        if hasattr(mod, "export"):
            return importlib.reload(mod)
        errors.append("%s (no export())" % name)
    raise SwarfError("FreeCAD's LinuxCNC post processor was not found: " +
                     "; ".join(errors))


def freecad_post_list(job):
    """The objects FreeCAD's own Post command would post for `job` (fixtures,
    tool controllers at tool changes, operations, in the Job's OrderOutputBy),
    as one list; None where this FreeCAD keeps that code somewhere unknown."""
    for name in ("PathScripts.PathPost", "Path.Post.Command"):
        try:
            mod = importlib.import_module(name)
        except Exception:  # a GUI-only import in some versions
            continue
        cmd = getattr(mod, "CommandPathPost", None)
        if cmd is None or not hasattr(cmd, "buildPostList"):
            continue
        try:
            lists = cmd().buildPostList(job)
        except (TypeError, AttributeError):  # another version's signature
            continue
        # 1.0 returns (name, objects) pairs; 0.20 and 0.21 lists of objects.
        flat = []
        for sub in lists:
            if isinstance(sub, tuple) and len(sub) == 2:
                sub = sub[1]
            flat.extend(sub)
        return flat
    return None


def is_job(obj):
    """A Path/CAM Job (its proxy is the ObjectJob class of any version)."""
    proxy = getattr(obj, "Proxy", None)
    return proxy is not None and type(proxy).__name__ == "ObjectJob"


def jobs(doc):
    return [o for o in doc.Objects if is_job(o)] if doc else []
