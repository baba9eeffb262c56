"""The developer API's pages and the resolution of the packages' own cross-references.

* ``.. internal-modules::`` (``docs/api/internals.rst``) — a table of modules, one page each,
  generated at ``builder-inited`` under ``docs/api/generated/internals/``: the module's
  docstring and every documented name it defines, except the names the public pages document
  (those link to their public page);
* a reference the pages do not document under that exact name resolves as Python reads it
  where the docstring stands (:func:`resolve_same_object`): re-exports
  (``observer.engines.ENGINES`` is ``observer.ENGINES``), names of the docstring's module or
  class, members of a documented class; external objects are reported under their full name;
* the docstrings' plain-text math (``|A|``) is not read as reST substitutions.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import re
import sys
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive

API = Path(__file__).resolve().parents[1] / "api"
PUBLIC_PAGES = ("observer.rst", "proofs_checks.rst", "stats.rst")
"""The public API's pages (``docs/api/``): their ``autosummary`` tables are the public names."""
INTERNALS_PAGE = API / "internals.rst"
INTERNALS_DIR = "generated/internals"
"""Where the internal modules' pages are written, relative to ``docs/api/`` (not tracked)."""


def _directive_blocks(text: str, directive: str) -> list[tuple[str, list[str]]]:
    """(argument, content lines) of every ``.. directive::`` block of an reST source."""
    blocks = []
    lines = text.splitlines()
    for i, line in enumerate(lines):
        m = re.match(rf"\.\. {re.escape(directive)}::\s*(.*)$", line)
        if not m:
            continue
        content = []
        for body in lines[i + 1:]:
            if body.strip() and not body.startswith(" "):
                break
            if body.strip() and not body.strip().startswith(":"):
                content.append(body.strip())
        blocks.append((m.group(1).strip(), content))
    return blocks


def public_names() -> list[str]:
    """Fully qualified names the public pages document (their ``autosummary`` entries, under
    the ``currentmodule`` in force), and the modules they ``automodule``."""
    names = []
    for page in PUBLIC_PAGES:
        text = (API / page).read_text(encoding="utf-8")
        names += [arg for arg, _ in _directive_blocks(text, "automodule")]
        current = None
        for line in text.splitlines():
            m = re.match(r"\.\. currentmodule::\s*(\S+)", line)
            if m:
                current = m.group(1)
            m = re.match(r"^   ([A-Za-z_]\w*)\s*$", line)
            if m and current:
                names.append(f"{current}.{m.group(1)}")
    return names


def internal_modules() -> list[str]:
    """The modules listed by the ``internal-modules`` blocks of ``docs/api/internals.rst``."""
    text = INTERNALS_PAGE.read_text(encoding="utf-8")
    return [m for _, content in _directive_blocks(text, "internal-modules") for m in content]


def _public_objects() -> dict[tuple[str, int], str]:
    """Public name's last component + id of its object -> the public name (a re-export keeps
    its name: ``observer.ENGINES`` is ``observer.engines.ENGINES``)."""
    out = {}
    for name in public_names():
        obj = _import(name)
        if obj is not _MISSING:
            out[(name.rpartition(".")[2], id(obj))] = name
    return out


_MISSING = object()
PACKAGES = ("observer", "proofs_checks")


def _module_prefix(parts: list[str]) -> int:
    """Length of the longest prefix of ``parts`` that is an importable module (0 if none)."""
    for i in range(len(parts), 0, -1):
        try:
            importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        return i
    return 0


def _getattrs(obj, names):
    for attr in names:
        obj = getattr(obj, attr, _MISSING)
        if obj is _MISSING:
            break
    return obj


def _import(name: str):
    """The object a dotted name denotes in Python: attributes from the top package first
    (``observer.simulate`` is the function), else the longest importable module and
    attributes of it (``observer.ensemble.run_members``)."""
    parts = name.split(".")
    if not all(parts):
        return _MISSING
    try:
        obj = importlib.import_module(parts[0])
    except ImportError:
        return _MISSING
    for i, attr in enumerate(parts[1:], start=2):
        if hasattr(obj, attr):
            obj = getattr(obj, attr)
            continue
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            obj = _MISSING
            break
    if obj is not _MISSING:
        return obj
    k = _module_prefix(parts)
    return _getattrs(importlib.import_module(".".join(parts[:k])), parts[k:]) if k else _MISSING


_ROLE = re.compile(r":(?:py:)?(?:func|meth|class|data|attr|obj|exc|const|mod):`(?:[^`<]*<)?[~.]*([\w.]+)>?`")


@functools.cache
def _referenced_names() -> dict[str, set[str]]:
    """Module -> its names that a docstring of the packages references although the module's
    page would not show them: private ones (``:func:`_advance_loop```,
    ``:meth:`observer.event.master._Run.land```) and data without a documentation comment
    (``:data:`SCHEMA```). They are documented on the module's page (data with its value)."""
    found: dict[str, set[str]] = {}
    for package in PACKAGES:
        root = Path(importlib.import_module(package).__file__).parent
        for path in root.rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            if "`_" not in text and "._" not in text:
                continue
            rel = path.relative_to(root.parent).with_suffix("").as_posix().replace("/", ".")
            where = rel.removesuffix(".__init__")
            for target in _ROLE.findall(text):
                parts = target.split(".")
                if parts[0] in PACKAGES:
                    k = _module_prefix(parts)
                    home, names = ".".join(parts[:k]), parts[k:]
                else:
                    home, names = where, parts
                if not names or names[0].startswith("__"):
                    continue
                owner = _defining_module(importlib.import_module(home), names[0])
                if owner and (names[0].startswith("_") or not _is_documented(owner, names[0])):
                    found.setdefault(owner, set()).add(names[0])
    return found


def _defining_module(module, name: str) -> str | None:
    """The module of the packages that defines ``module.name``: a class's or function's own,
    else the first module of the packages that assigns the name at its top level and holds
    the same object."""
    obj = getattr(module, name, _MISSING)
    if obj is _MISSING:
        return None
    if inspect.isclass(obj) or _is_routine(obj):
        return obj.__module__ if obj.__module__.split(".")[0] in PACKAGES else None
    for candidate in [module.__name__] + sorted(m for m in sys.modules if m.split(".")[0] in PACKAGES):
        held = getattr(sys.modules.get(candidate), name, _MISSING)
        if held is obj and name in _assigned_names(candidate):
            return candidate
    return None


@functools.cache
def _assigned_names(modname: str) -> frozenset[str]:
    """The names a module's top level assigns (``X = …``, ``A, B = …``, ``X: T = …``)."""
    import ast
    path = getattr(sys.modules.get(modname), "__file__", None)
    if not path or not path.endswith(".py"):
        return frozenset()
    names = set()
    for stmt in ast.parse(Path(path).read_text(encoding="utf-8")).body:
        targets = stmt.targets if isinstance(stmt, ast.Assign) else (
            [stmt.target] if isinstance(stmt, ast.AnnAssign) else [])
        for target in targets:
            for node in ast.walk(target):
                if isinstance(node, ast.Name):
                    names.add(node.id)
    return frozenset(names)


def _is_documented(modname: str, name: str) -> bool:
    """Has ``modname.name`` a docstring or documentation comment of its own?"""
    from sphinx.pycode import ModuleAnalyzer
    obj = getattr(importlib.import_module(modname), name)
    if inspect.isclass(obj) or _is_routine(obj):
        return bool(inspect.getdoc(obj))
    return ("", name) in ModuleAnalyzer.for_module(modname).find_attr_docs()


def _is_routine(obj) -> bool:
    """A function, or a numba dispatcher of one."""
    return inspect.isfunction(obj) or (callable(obj) and inspect.isfunction(getattr(obj, "py_func", None)))


def module_members(modname: str, public: dict, referenced: set[str] = frozenset()) -> list[tuple[str, str]]:
    """(autodoc directive, name) of the names ``modname`` defines and documents, in source
    order: its functions and classes with a docstring, its data with a documentation comment
    or string, and the ``referenced`` ones whatever they are; not private ones, not imported
    ones, not the public API's re-exports."""
    from sphinx.pycode import ModuleAnalyzer
    module = importlib.import_module(modname)
    analyzer = ModuleAnalyzer.for_module(modname)
    attr_docs = {name for (scope, name) in analyzer.find_attr_docs() if scope == ""}
    order = analyzer.tagorder
    out = []
    for name, obj in vars(module).items():
        if (name.startswith("_") and name not in referenced) or (name, id(obj)) in public:
            continue
        if inspect.isclass(obj) or _is_routine(obj):
            if getattr(obj, "__module__", None) != modname or not (inspect.getdoc(obj) or name in referenced):
                continue
            kind = ("autoexception" if inspect.isclass(obj) and issubclass(obj, BaseException)
                    else "autoclass" if inspect.isclass(obj) else "autofunction")
        elif name in attr_docs or name in referenced:
            kind = "autodata"
        else:
            continue
        out.append((kind, name))
    return sorted(out, key=lambda item: order.get(item[1], len(order)))


def internal_page(modname: str, public: dict, documented_elsewhere: set[str]) -> str:
    """The reST of one internal module's page."""
    title = f"``{modname}``"
    lines = [title, "=" * len(title), "", f".. automodule:: {modname}", "   :no-members:"]
    if modname in documented_elsewhere:   # observer.simulate is the function; observer.stats a page
        lines.append("   :no-index:")
    lines += ["", f".. currentmodule:: {modname}", ""]
    for kind, name in module_members(modname, public, _referenced_names().get(modname, set())):
        lines += [f".. {kind}:: {name}", ""]
    return "\n".join(lines) + "\n"


def write_internal_pages(app) -> None:
    """Write the pages of the modules of ``docs/api/internals.rst`` (only those that changed)."""
    out = API / INTERNALS_DIR
    out.mkdir(parents=True, exist_ok=True)
    public = _public_objects()
    elsewhere = set(public_names())
    for modname in internal_modules():
        page = out / f"{modname}.rst"
        text = internal_page(modname, public, elsewhere)
        if not page.is_file() or page.read_text(encoding="utf-8") != text:
            page.write_text(text, encoding="utf-8")


class InternalModules(Directive):
    """A table of modules (name, first paragraph of its docstring), each linked to its page;
    the summary's references are read in the module's namespace."""

    has_content = True

    def _cell(self, text: str, module: str) -> nodes.entry:
        from docutils.statemachine import StringList
        env = self.state.document.settings.env
        saved = env.ref_context.get("py:module")
        env.ref_context["py:module"] = module
        entry = nodes.entry()
        try:
            self.state.nested_parse(StringList([text], source=f"docstring of {module}"),
                                    self.content_offset, entry)
        finally:
            if saved is None:
                env.ref_context.pop("py:module", None)
            else:
                env.ref_context["py:module"] = saved
        return entry

    def run(self):
        from docutils.statemachine import StringList
        table = nodes.table()
        group = nodes.tgroup(cols=2)
        table += group
        group += [nodes.colspec(colwidth=35), nodes.colspec(colwidth=65)]
        body = nodes.tbody()
        group += body
        for modname in self.content:
            doc = inspect.getdoc(importlib.import_module(modname)) or ""
            summary = _escape_bars(" ".join(doc.strip().split("\n\n")[0].split()))
            row = nodes.row()
            row += self._cell(f":doc:`{modname} <{INTERNALS_DIR}/{modname}>`", modname)
            row += self._cell(summary, modname)
            body += row
        toc = nodes.container()
        self.state.nested_parse(StringList([".. toctree::", "   :hidden:", "",
                                            *[f"   {INTERNALS_DIR}/{m}" for m in self.content]],
                                           source=self.state.document["source"]),
                                self.content_offset, toc)
        return [table, *toc.children]


_INLINE = re.compile(r"(``.+?``|:[\w:+-]+:`[^`]*`|`[^`]*`_{0,2})")
_DIRECTIVE = re.compile(r"^\s*\.\. [\w:+-]+::")


def escape_bars(app, what, name, obj, options, lines: list[str]) -> None:
    """The project's docstrings write norms and absolute values as plain text (``|A|``,
    ``|g| ≤ tol``), never reST substitutions: escape each ``|`` outside literals, roles,
    literal blocks and doctests, so that docutils reads it as the character it is."""
    literal_indent = None
    for i, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None:
            if not line.strip() or indent > literal_indent:
                continue
            literal_indent = None
        stripped = line.strip()
        if stripped.endswith("::") or _DIRECTIVE.match(line):
            literal_indent = indent
        if stripped.startswith(">>>") or "|" not in line:
            continue
        lines[i] = _escape_bars(line)


def _escape_bars(line: str) -> str:
    """``line`` with each ``|`` outside inline literals and roles escaped."""
    pieces = _INLINE.split(line)
    return "".join(p if k % 2 else p.replace("|", "\\|") for k, p in enumerate(pieces))


def drop_type_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    """A constant without a documentation comment shows its value, not its type's docstring
    (``REQUIRED``, a tuple, is not "Built-in immutable sequence")."""
    if what not in ("data", "attribute") or inspect.isclass(obj) or _is_routine(obj):
        return
    first = (inspect.getdoc(type(obj)) or "").strip().split("\n")[0].strip()
    if first and any(line.strip() == first for line in lines):
        lines[:] = []


def skip_builtin_inherited(app, what, name, obj, skip, options):
    """Skip a class member that has no docstring of its own but would inherit one from a
    class outside the packages (``ReadOnlyDict.clear`` is not ``dict.clear``, ``Parser.error``
    not argparse's)."""
    if what not in ("class", "exception") or getattr(obj, "__doc__", "") is not None:
        return None
    owner = _import(f"{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', '').rpartition('.')[0]}")
    bases = owner.__mro__[1:] if inspect.isclass(owner) else (dict, list, tuple, str, object)
    if any(name in vars(base) and base.__module__.split(".")[0] not in PACKAGES for base in bases):
        return True
    return None


def _documented_attributes(cls) -> set[str]:
    """Attribute names a class documents: its numpydoc ``Attributes`` section, its dataclass
    or named-tuple fields, its annotations, the attributes its ``__init__`` sets."""
    from numpydoc.docscrape import ClassDoc
    names = set(getattr(cls, "__annotations__", {})) | set(getattr(cls, "_fields", ()))
    names |= set(getattr(cls, "__dataclass_fields__", {}))
    try:
        section = ClassDoc(cls, config={"show_class_members": False})["Attributes"]
    except Exception:        # a docstring numpydoc cannot parse documents no attribute
        section = []
    for param in section:
        names |= {n.strip() for n in param.name.split(",")}
    init = vars(cls).get("__init__")
    if inspect.isfunction(init):            # instance attributes: self.x = … in __init__
        import ast
        import textwrap
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(init)))
        except (OSError, TypeError):      # generated (a dataclass's): its fields are above
            tree = ast.parse("")
        names |= {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)
                  and isinstance(node.value, ast.Name) and node.value.id == "self"
                  and isinstance(node.ctx, ast.Store)}
    return names


def _scopes(module: str | None, cls: str | None, source: str | None) -> list:
    """Where a relative name in a docstring is read, innermost first: the enclosing class and
    its module, the object whose docstring holds the reference and its module, the current
    module."""
    scopes = []

    def add(obj):
        if obj is _MISSING or obj is None:
            return
        if inspect.isclass(obj) and obj not in scopes:
            scopes.append(obj)
        home = obj if inspect.ismodule(obj) else sys.modules.get(getattr(obj, "__module__", None) or "")
        if home is not None and home not in scopes:
            scopes.append(home)

    if module and cls:
        add(_import(f"{module}.{cls}"))
    m = re.search(r"docstring of ([\w.]+)$", source or "")
    if m and m.group(1).split(".")[0] in PACKAGES:
        obj = _import(m.group(1))
        owner = _import(m.group(1).rpartition(".")[0])
        if inspect.isclass(owner):
            add(owner)
        add(obj)
    if module and module.split(".")[0] in PACKAGES:
        add(importlib.import_module(module))
    return scopes


def _lookup(target: str, scopes: list):
    """(object, name path) that ``target`` denotes: an absolute ``observer.…`` or
    ``proofs_checks.…`` name, else a name read in the first scope that has it."""
    parts = target.split(".")
    if parts[0] in PACKAGES:
        k = _module_prefix(parts)
        return (_import(target), ".".join(parts[k:])) if k < len(parts) else (_MISSING, target)
    for scope in scopes:
        obj = _getattrs(scope, parts)
        if obj is not _MISSING:
            return obj, target
    return _MISSING, target


def _same(a, b) -> bool:
    """One object (a class's method read twice is one function; a classmethod's binding too)."""
    return a is b or (getattr(a, "__func__", a) is getattr(b, "__func__", b))


def _documented_as(domain, obj, path: str) -> str | None:
    """The shortest documented name of ``obj`` that ends in ``path``."""
    names = sorted(name for name in domain.objects
                   if name.split(".")[0] in PACKAGES and (name == path or name.endswith("." + path))
                   and _same(_import(name), obj))
    return min(names, key=len) if names else None


def _only_documented(domain, path: str) -> str | None:
    """The one documented name of the packages ending in ``.path`` (Sphinx's own search for
    ``.name``), if exactly one does."""
    names = sorted((name for name in domain.objects
                    if name.split(".")[0] in PACKAGES and name.endswith("." + path)), key=len)
    if not names or any(not _same(_import(name), _import(names[0])) for name in names[1:]):
        return None
    return names[0]


def resolve_same_object(app, env, node, contnode):
    """Resolve a reference the pages do not document under that exact name, as Python reads
    it where the docstring stands, to the documented name of the same object:

    * a re-export: ``observer.engines.ENGINES`` is documented as ``observer.ENGINES``;
    * a name of the docstring's own module or class: ``InputError`` in a docstring of
      :mod:`observer.scenario` is ``observer.InputError``;
    * a bare name that the docstring's module does not import, when exactly one documented
      name of the packages ends in it (as Sphinx's own ``.name`` search);
    * a member of a documented class that has no entry of its own (an attribute of its
      ``Attributes`` section, a field, an undocumented method): the class.

    Only names of this project's packages; a name that Python cannot find stays unresolved. A
    name that Python reads as an object of another package (``Path`` in a module that
    imported it) is reported under that object's full name (``pathlib.Path``), so that the
    explicit list of external names in ``conf.py`` applies to it."""
    if node.get("refdomain") != "py":
        return None
    from sphinx.util.nodes import get_node_source
    try:
        source = get_node_source(node)
    except ValueError:
        source = None
    domain = env.get_domain("py")
    target = node.get("reftarget", "")
    scopes = _scopes(node.get("py:module"), node.get("py:class"), source)
    obj, path = _lookup(target, scopes)
    best = _documented_as(domain, obj, path) if obj is not _MISSING else None
    if best is None and obj is _MISSING and target.split(".")[0] not in PACKAGES:
        best = _only_documented(domain, target)   # a name of a module that this one does not import
    if best is None:                      # a member: the class that documents it
        owner_path, _, attr = target.rpartition(".")
        if not owner_path:
            owner = next((s for s in scopes if inspect.isclass(s)), _MISSING)
        else:
            owner = _lookup(owner_path, scopes)[0]
            if owner is _MISSING and owner_path.split(".")[0] not in PACKAGES:
                documented = _only_documented(domain, owner_path)
                owner = _import(documented) if documented else _MISSING
        if inspect.isclass(owner) and (hasattr(owner, attr) or attr in _documented_attributes(owner)):
            best = _documented_as(domain, owner, owner.__qualname__)
            if best is not None:
                return domain.resolve_xref(env, node["refdoc"], app.builder, "class", best, node, contnode)
        if obj is not _MISSING and getattr(obj, "__module__", None) and \
                obj.__module__.split(".")[0] not in PACKAGES and hasattr(obj, "__qualname__"):
            node["external_target"] = f"{obj.__module__}.{obj.__qualname__}"   # see below
        return None
    return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], best, node, contnode)


def ignore_external(app, domain, node):
    """Apply ``nitpick_ignore_regex`` to the full name of an external object that a
    docstring names as its module imported it (``Path`` for ``pathlib.Path``)."""
    name = node.get("external_target")
    kind = f"{node.get('refdomain')}:{node.get('reftype')}"
    if name and any(re.fullmatch(role, kind) and re.fullmatch(target, name)
                    for role, target in app.config.nitpick_ignore_regex):
        return True
    return None


def anchor_defining_module(app, doctree) -> None:
    """Give each signature of a re-exported object a second anchor under the module that
    defines it (``observer.LinearSystem.energy`` also ``observer.model.LinearSystem.energy``):
    the "[docs]" links of the highlighted source (``sphinx.ext.viewcode``, one set of links per
    module, under the module's own name) land on it."""
    from sphinx import addnodes
    for sig in doctree.findall(addnodes.desc_signature):
        module, fullname = sig.get("module"), sig.get("fullname")
        if not module or not fullname or module.split(".")[0] not in PACKAGES:
            continue
        top = _import(f"{module}.{fullname.split('.')[0]}")
        home = getattr(top, "__module__", None) if (inspect.isclass(top) or _is_routine(top)) else None
        if home and home != module and home.split(".")[0] in PACKAGES:
            anchor = f"{home}.{fullname}"
            if anchor not in sig["ids"] and anchor not in doctree.ids:
                sig["ids"].append(anchor)
                doctree.ids[anchor] = sig


def setup(app):
    app.add_directive("internal-modules", InternalModules)
    app.connect("builder-inited", write_internal_pages)
    app.connect("missing-reference", resolve_same_object)
    app.connect("warn-missing-reference", ignore_external)
    app.connect("doctree-read", anchor_defining_module)
    app.connect("autodoc-process-docstring", escape_bars)
    app.connect("autodoc-process-docstring", drop_type_docstring, priority=400)
    app.connect("autodoc-skip-member", skip_builtin_inherited)
    return {"version": "1", "parallel_read_safe": True}
