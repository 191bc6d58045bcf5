# The parts of FreeCAD's Path/CAM workbench the add-on uses, found where each
# version keeps them: FreeCAD 0.20 names the workbench "Path" and keeps its
# Python in PathScripts; 0.21 and 1.0 (where it is "CAM") moved it into the
# Path package (Path.Main.Job, Path.Post.Command, Path.Post.scripts). Nothing
# here imports FreeCADGui, so it all runs under freecadcmd.
import importlib


class SwarfError(Exception):
    """An error the user can act on; the message names the object or file."""


def _first_module(names):
    errors = []
    for name in names:
        try:
            return importlib.import_module(name)
        except ImportError as e:  # the next version's location
            errors.append("%s (%s)" % (name, e))
    raise SwarfError("none of these FreeCAD modules could be imported: " +
                     "; ".join(errors))


def linuxcnc_post():
    """FreeCAD's LinuxCNC post processor module, freshly loaded: the post keeps
    its settings (and line counter) in module globals, so every posting starts
    from a reload, as FreeCAD's own PostProcessor.load does."""
    mod = _first_module([
        "PathScripts.post.linuxcnc_post",  # 0.20
        "Path.Post.scripts.linuxcnc_post",  # 0.21, 1.0
    ])
    return importlib.reload(mod)


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
        lists = cmd().buildPostList(job)
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
