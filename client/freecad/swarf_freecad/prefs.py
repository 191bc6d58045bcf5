# The add-on's preferences, in FreeCAD's parameter tree
# (User parameter:BaseApp/Preferences/Mod/swarf), read the same way by the
# GUI command and by simulate-job (which a flag overrides).
from .simulate import Options

GROUP = "User parameter:BaseApp/Preferences/Mod/swarf"

# name -> (kind, default, text shown in the preferences page)
FIELDS = [
    ("SwarfPath", "str", "swarf", "swarf CLI (path, or a name on PATH)"),
    ("Server", "str", "", "swarfd address HOST:PORT (empty: none)"),
    ("Token", "str", "", "bearer token"),
    ("TlsCa", "str", "", "TLS: CA certificate (PEM; given: use TLS)"),
    ("TlsCert", "str", "", "TLS: client certificate (PEM)"),
    ("TlsKey", "str", "", "TLS: client key (PEM)"),
    ("SwarfdPath", "str", "",
     "swarfd to start locally when no address is given (empty: swarf's "
     "embedded server)"),
    ("Spacing", "float", 0.0, "grid spacing mm (0: swarf's default)"),
    ("Tolerance", "float", 0.0, "tolerance mm (0: swarf's default)"),
    ("Allowance", "float", 0.0, "allowance (stock to leave) mm"),
    ("CompareDesign", "bool", True, "compare with the Job's model"),
    ("Deflection", "float", 0.01,
     "the model's tessellation: largest chord error (mm)"),
    ("OutputDir", "str", "",
     "output folder (empty: a folder beside the document, or in /tmp)"),
    ("ColorBy", "str", "deviation", "colour the surface by: deviation or height"),
]


def _group():
    import FreeCAD
    return FreeCAD.ParamGet(GROUP)


def get(name):
    kind, default = {f[0]: (f[1], f[2]) for f in FIELDS}[name]
    g = _group()
    if kind == "str":
        return g.GetString(name, default)
    if kind == "float":
        return g.GetFloat(name, default)
    return g.GetBool(name, default)


def set(name, value):
    kind = {f[0]: f[1] for f in FIELDS}[name]
    g = _group()
    if kind == "str":
        g.SetString(name, value)
    elif kind == "float":
        g.SetFloat(name, float(value))
    else:
        g.SetBool(name, bool(value))


def options():
    """Options from the preferences."""
    return Options(
        swarf=get("SwarfPath") or "swarf", server=get("Server"),
        token=get("Token"), tls_ca=get("TlsCa"), tls_cert=get("TlsCert"),
        tls_key=get("TlsKey"), swarfd=get("SwarfdPath"),
        spacing=get("Spacing") or None, design=get("CompareDesign"),
        tolerance=get("Tolerance") or None,
        allowance=get("Allowance") or None, color_by=get("ColorBy"),
        deflection=get("Deflection") or 0.01)
