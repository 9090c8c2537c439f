"""Slicing a reproducer's code to what its fixed numbers reach (cross_checks/sweep/repro_text.py calls it;
docs/repro.md, "Length").

A script runs rbcheck's world and measurement on the numbers it embeds (``BODIES``, ``VARIANT``,
``QUANTITY``, …). Some of that code is there for numbers this script does not hold: the welded-parts loop of
a body with no parts, another quantity's error, another variant's branch. :func:`prune` removes it, and only
it: an ``if`` whose test, or a ``for`` whose iterable, is decided by the embedded numbers alone, the same way
for every value they can take here; never one that depends on what the engine computes (an ``if`` on an error,
a divergence, a state), which another engine version may decide the other way.

How it decides (a sound, conservative static analysis of the script's own text; it runs nothing):

* values are followed from the script's module-level constants (its numbers and the worlds' constants) and
  ``globals()`` through the parameters of its functions and of its classes' methods: a parameter's possible
  values are the union of what every call site passes (its default where a call leaves it out; a method's,
  every ``x.name(...)`` of that name, whatever ``x``), a local's the union of every assignment to it
  (flow-insensitive; a comprehension's variables count as the function's), an attribute's (``self.x``) the
  union of every store to ``.x`` anywhere in the script. Only pure operations are evaluated: literals,
  names, subscripts, comparisons, ``and``/``or``/``not``, arithmetic, conditional expressions, a few
  builtins (:data:`_BUILTINS`) and the methods of strings, numbers and tuples. Anything else (a call into the
  engine, NumPy, an object's attribute but the instance's own, the return value of a function) is unknown;
* a function or method that escapes (passed to code the analysis does not follow, stored, returned, a bound
  method taken), a decorated one, a special method, a nested function or a lambda, one called with
  ``*args``/``**kwargs``, and every method and attribute of a script that reaches attributes by computed
  names (``getattr`` on anything but a module, ``setattr``, ``vars``): its parameters are unknown; a
  parameter some running call passes a value with no possible value found for (a binding the analysis does
  not model) is unknown too;
* the script's own code must not mutate a value it follows (``x.append``, ``x[i] = …``, ``x += …`` on a
  followed list or dict): a fresh container (a local, an attribute or a module constant every assignment
  of which builds a new one: ``errors = []``) is then unknown, and any other such mutation leaves the script
  unsliced. Libraries (the engine, NumPy) are taken not to mutate the Python lists they are given (they
  copy them into their own types);
* an ``if`` is sliced when every value its test can take is false (its ``else`` block, if any, stays, one
  indentation level out) or every one is true (its body stays); the statements after it in its block go
  when the block kept ends in ``return`` or ``raise``; a ``for`` goes when every iterable it can loop over is
  empty. An ``elif`` chain, a block that would be left empty, a block holding a multi-line string (whose text
  its indentation is part of), and a statement whose test the analysis cannot evaluate are left as they are.

tests/cross_checks/sweep/test_repro_slice.py checks that sliced scripts print what the unsliced ones print, to
the character, with the same exit code, for every claim and several engines.
"""
from __future__ import annotations

import ast
import io
import itertools
import tokenize

__all__ = ["prune"]

_TOP = object()            # an unknown value set
_CAP = 64                  # more possible values than this: unknown
_MUTATORS = {"append", "extend", "insert", "pop", "remove", "clear", "update", "setdefault", "sort",
             "reverse", "popitem", "add", "discard", "__setitem__", "__delitem__", "__iadd__"}
#: builtins evaluated on known values (pure; the iterators materialised as lists)
_BUILTINS = {"len": len, "enumerate": lambda *a: list(enumerate(*a)), "zip": lambda *a: list(zip(*a)),
             "range": range, "float": float, "int": int, "str": str, "bool": bool, "tuple": tuple,
             "list": list, "dict": dict, "min": min, "max": max, "abs": abs, "any": any, "all": all,
             "sorted": sorted, "isinstance": isinstance, "reversed": lambda a: list(reversed(a))}
_TYPES = {"list": list, "tuple": tuple, "dict": dict, "float": float, "int": int, "str": str, "bool": bool}
_FRESH_CALLS = {"list", "dict", "set"}


class _Ref:
    """A top-level function or class of the script, as a value."""

    def __init__(self, name):
        self.name = name

    def __eq__(self, other):
        return isinstance(other, _Ref) and other.name == self.name

    def __hash__(self):
        return hash(self.name)


class _Globals(dict):
    """``globals()``: the module's known constants; any other name is unknown."""


class _Unknown(Exception):
    pass


def _union(a, b):
    if a is _TOP or b is _TOP:
        return _TOP
    out = list(a)
    for v in b:
        if not any(_same(v, w) for w in out):
            out.append(v)
    return _TOP if len(out) > _CAP else out


def _same(a, b) -> bool:
    try:
        return type(a) is type(b) and bool(a == b)
    except Exception:  # noqa: BLE001 - a comparison that raises: not the same
        return False


def _scope_nodes(fn):
    """The nodes of a function's own scope, its comprehensions' included (their variables are taken as the
    function's: a union, so no less than either), not those of nested functions, classes or lambdas."""
    stack = list(fn.body) if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef | ast.Module) else [fn]
    while stack:
        node = stack.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef | ast.Lambda):
                stack.append(child)


class _Analysis:
    def __init__(self, tree: ast.Module):
        self.tree = tree
        names = {n.name for n in tree.body if isinstance(n, ast.ClassDef)}
        #: classes followed: undecorated, their bases the script's own classes (no library sets their
        #: attributes or calls their methods)
        self.classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef) and not n.decorator_list
                        and not n.keywords and all(isinstance(b, ast.Name) and b.id in names | {"object"}
                                                   for b in n.bases)}
        #: functions and methods ("Class.method"), each a scope of its own
        self.defs = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
        self.defs.update({f"{c}.{m.name}": m for c, cls in self.classes.items() for m in cls.body
                          if isinstance(m, ast.FunctionDef)})
        self.params = {name: {} for name in self.defs}       # function -> param -> value set
        self.locals = {name: {} for name in self.defs}       # function -> local -> value set
        self.local_names = {name: self._assigned(fn) for name, fn in self.defs.items()}
        self.forced_top = {name: set() for name in self.defs}
        self.called: set = set()                             # functions some call site binds
        self.attrs: dict = {}                                # attribute name -> value set
        self.forced_attrs: set = set()
        # decorated (a wrapper calls it), or a special method the language calls: its parameters unknown
        self.escaped = {k for k, fn in self.defs.items() if fn.decorator_list
                        or ("." in k and fn.name.startswith("__") and fn.name != "__init__")}
        self.consts: dict = {}
        self.consts = self._module_constants()
        self.parents = {}
        for node in ast.walk(tree):
            for child in ast.iter_child_nodes(node):
                self.parents[child] = node
        self.dynamic = self._dynamic()
        #: code that may rebind anything (exec, eval, a store into globals()): nothing is sliced
        self.opaque = any(
            (isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in ("exec", "eval"))
            or (isinstance(n, ast.Subscript) and not isinstance(n.ctx, ast.Load)
                and isinstance(n.value, ast.Call) and isinstance(n.value.func, ast.Name)
                and n.value.func.id == "globals")
            or (isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr in _MUTATORS
                and isinstance(n.func.value, ast.Call) and isinstance(n.func.value.func, ast.Name)
                and n.func.value.func.id == "globals")
            for n in ast.walk(tree))
        # an instance made without naming its class (type(x)(…), x.__class__(…)): no __init__ is followed
        def made_unnamed(n) -> bool:
            f = getattr(n, "func", None)
            return isinstance(n, ast.Call) and (
                (isinstance(f, ast.Call) and isinstance(f.func, ast.Name) and f.func.id == "type")
                or (isinstance(f, ast.Attribute) and f.attr == "__class__"))
        if any(made_unnamed(n) for n in ast.walk(tree)):
            self.escaped |= {k for k in self.defs if k.endswith(".__init__")}

    def _dynamic(self) -> bool:
        """True where the script reaches attributes by computed names (getattr/setattr/delattr with a name
        that is no constant, on anything but a module's attribute; vars(), __dict__): then no method's
        parameters and no attribute are followed."""
        imported = {t.id for node in self.tree.body if isinstance(node, ast.Import | ast.ImportFrom)
                    for t in self._targets(node)}
        for node in ast.walk(self.tree):
            if isinstance(node, ast.Attribute) and node.attr == "__dict__":
                return True
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
                continue
            if node.func.id == "vars":
                return True
            if node.func.id in ("getattr", "setattr", "delattr", "hasattr") and (
                    len(node.args) < 2 or not isinstance(node.args[1], ast.Constant)):
                root = node.args[0] if node.args else None
                while isinstance(root, ast.Attribute):
                    root = root.value
                if not (isinstance(root, ast.Name) and root.id in imported):
                    return True
        return False

    # --- scopes -------------------------------------------------------------------------------------
    def _assigned(self, fn) -> set:
        names = {a.arg for a in fn.args.args + fn.args.posonlyargs + fn.args.kwonlyargs}
        names |= {a.arg for a in (fn.args.vararg, fn.args.kwarg) if a is not None}
        for node in _scope_nodes(fn):
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store | ast.Del):
                names.add(node.id)
            elif isinstance(node, ast.Global | ast.Nonlocal):
                names |= set(node.names)
            elif isinstance(node, ast.Import | ast.ImportFrom):
                names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        return names

    def _module_constants(self) -> dict:
        declared_global = {n for fn in ast.walk(self.tree) if isinstance(fn, ast.Global) for n in fn.names}
        counts: dict = {}   # every binding at module scope (in an if, a loop, a with, a del too)
        for node in _scope_nodes(self.tree):
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store | ast.Del):
                counts[node.id] = counts.get(node.id, 0) + 1
            if isinstance(node, ast.Import | ast.ImportFrom | ast.ClassDef):
                for t in self._targets(node):
                    counts[t.id] = counts.get(t.id, 0) + 1
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                counts[node.name] = counts.get(node.name, 0) + 1
        consts: dict = {}
        for node in self.tree.body:
            if isinstance(node, ast.Assign) and len(node.targets) == 1:
                vals = self._eval(node.value, None, consts)
                self._bind(node.targets[0], vals, consts)
            elif isinstance(node, ast.AugAssign | ast.AnnAssign | ast.For | ast.With | ast.Import
                            | ast.ImportFrom | ast.ClassDef | ast.Assign):
                for t in self._targets(node):
                    for n in ast.walk(t):
                        if isinstance(n, ast.Name):
                            consts[n.id] = _TOP
        for name in list(consts):
            if counts.get(name, 0) > 1 or name in declared_global:
                consts[name] = _TOP
        for name in list(self.defs) + list(self.classes):
            if "." not in name:
                consts[name] = [_Ref(name)] if counts.get(name, 0) <= 1 else _TOP
        return consts

    @staticmethod
    def _targets(node) -> list:
        if isinstance(node, ast.Assign):
            return list(node.targets)
        if isinstance(node, ast.AugAssign | ast.AnnAssign | ast.For):
            return [node.target]
        if isinstance(node, ast.With):
            return [i.optional_vars for i in node.items if i.optional_vars is not None]
        if isinstance(node, ast.Import | ast.ImportFrom):
            return [ast.Name(id=(a.asname or a.name).split(".")[0], ctx=ast.Store()) for a in node.names]
        if isinstance(node, ast.ClassDef):
            return [ast.Name(id=node.name, ctx=ast.Store())]
        return []

    def _bind(self, target, vals, env) -> None:
        """Add the values ``vals`` bound to ``target`` (a Name, or a tuple of them) into ``env``."""
        if isinstance(target, ast.Name):
            env[target.id] = _union(env.get(target.id, []), vals)
            return
        if isinstance(target, ast.Tuple | ast.List):
            names = [e for e in target.elts]
            if vals is not _TOP and not any(isinstance(e, ast.Starred) for e in names):
                split: list = [[] for _ in names]
                try:
                    for v in vals:
                        items = list(v)
                        if len(items) != len(names):
                            raise _Unknown
                        for i, item in enumerate(items):
                            split[i] = _union(split[i], [item])
                except (_Unknown, TypeError):
                    split = [_TOP] * len(names)
                for e, s in zip(names, split):
                    self._bind(e, s, env)
                return
            for e in names:
                self._bind(e.value if isinstance(e, ast.Starred) else e, _TOP, env)
        # a subscript or attribute target binds no name (its mutation is checked apart)

    # --- values -------------------------------------------------------------------------------------
    def _lookup(self, name, fn, env):
        if fn is not None and name in self.local_names[fn]:
            if name in self.forced_top[fn]:
                return _TOP
            return env.get(name, [])
        if fn is None and env is not None and name in env and env is not self.consts:
            return env[name]
        if name in self.consts:
            return self.consts[name]
        if name == "globals":
            return ["globals"]
        if name in _BUILTINS or name in _TYPES or name in ("None", "True", "False"):
            return [_BUILTINS.get(name) or _TYPES[name]]
        return _TOP

    def _eval(self, node, fn, env):
        """The values ``node`` can take in function ``fn`` (None: module level) with names in ``env``."""
        try:
            return self._eval_(node, fn, env)
        except (_Unknown, RecursionError):
            return _TOP

    def _each(self, nodes, fn, env):
        sets = [self._eval(n, fn, env) for n in nodes]
        if any(s is _TOP for s in sets):
            raise _Unknown
        combos = list(itertools.islice(itertools.product(*sets), _CAP + 1))
        if len(combos) > _CAP:
            raise _Unknown
        return combos

    def _apply(self, combos, f):
        out: list = []
        for c in combos:
            try:
                out = _union(out, [f(*c)])
            except _Unknown:
                raise
            except Exception:  # noqa: BLE001 - what would raise at run time: not decided here
                raise _Unknown from None
            if out is _TOP:
                raise _Unknown
        return out

    def _eval_(self, node, fn, env):
        if isinstance(node, ast.Constant):
            return [node.value]
        if isinstance(node, ast.Name):
            return self._lookup(node.id, fn, env)
        if isinstance(node, ast.Tuple | ast.List):   # a starred element spliced in: (*body[:3], com)
            make = tuple if isinstance(node, ast.Tuple) else list
            starred = [isinstance(e, ast.Starred) for e in node.elts]
            parts = [e.value if isinstance(e, ast.Starred) else e for e in node.elts]
            return self._apply(self._each(parts, fn, env), lambda *v: make(
                x for value, star in zip(v, starred) for x in (_splice(value) if star else (value,))))
        if isinstance(node, ast.Dict) and None not in node.keys:
            n = len(node.keys)
            return self._apply(self._each(node.keys + node.values, fn, env),
                               lambda *v: dict(zip(v[:n], v[n:])))
        if isinstance(node, ast.Subscript):
            if isinstance(node.slice, ast.Slice):
                parts = [node.slice.lower, node.slice.upper, node.slice.step]
                got = [p if p is not None else ast.Constant(None) for p in parts]
                return self._apply(self._each([node.value, *got], fn, env),
                                   lambda v, a, b, c: _index(v, slice(a, b, c)))
            return self._apply(self._each([node.value, node.slice], fn, env), _index)
        if isinstance(node, ast.Compare):
            ops = node.ops
            return self._apply(self._each([node.left, *node.comparators], fn, env),
                               lambda *v: all(_compare(o, a, b) for o, a, b in zip(ops, v, v[1:])))
        if isinstance(node, ast.BoolOp):
            return self._boolop(node, fn, env)
        if isinstance(node, ast.UnaryOp):
            op = {ast.Not: lambda a: not a, ast.USub: lambda a: -a, ast.UAdd: lambda a: +a}.get(type(node.op))
            if op is None:
                raise _Unknown
            return self._apply(self._each([node.operand], fn, env), op)
        if isinstance(node, ast.BinOp):
            op = _BINOPS.get(type(node.op))
            if op is None:
                raise _Unknown
            return self._apply(self._each([node.left, node.right], fn, env), op)
        if isinstance(node, ast.IfExp):
            out: list = []
            for t in self._apply(self._each([node.test], fn, env), bool):
                out = _union(out, self._eval(node.body if t else node.orelse, fn, env))
                if out is _TOP:
                    raise _Unknown
            return out
        if isinstance(node, ast.Call):
            return self._call(node, fn, env)
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and fn in self.defs
                and "." in fn and self.defs[fn].args.args and node.value.id == self.defs[fn].args.args[0].arg
                and not self.dynamic):
            vals = self.attrs.get(node.attr, _TOP)    # an attribute of the instance (self.x)
            if vals is _TOP or node.attr in self.method_names():
                raise _Unknown
            return vals
        raise _Unknown

    def _boolop(self, node, fn, env):
        is_and = isinstance(node.op, ast.And)
        out: list = []
        for v in self._apply(self._each([node.values[0]], fn, env), lambda a: a):
            if len(node.values) == 1 or (not v if is_and else v):
                out = _union(out, [v])
            else:
                rest = ast.BoolOp(op=node.op, values=node.values[1:])
                out = _union(out, self._boolop(rest, fn, env) if len(node.values) > 2
                             else self._eval(node.values[1], fn, env))
            if out is _TOP:
                raise _Unknown
        return out

    def _call(self, node, fn, env):
        if any(isinstance(a, ast.Starred) for a in node.args) or any(k.arg is None for k in node.keywords):
            raise _Unknown
        if isinstance(node.func, ast.Attribute):    # a method of a string, a number, a tuple, a dict's get
            name = node.func.attr
            if name.startswith("_"):
                raise _Unknown

            def method(obj, *args):
                if isinstance(obj, str | int | float | tuple) or (
                        isinstance(obj, dict) and name in ("get", "keys", "values", "items")):
                    return getattr(obj, name)(*args)
                raise _Unknown
            return self._apply(self._each([node.func.value, *node.args], fn, env), method)
        funcs = self._eval(node.func, fn, env)
        if funcs is _TOP:
            raise _Unknown
        keys, n = [k.arg for k in node.keywords], len(node.args)
        out: list = []
        for f in funcs:
            if isinstance(f, _Ref):
                raise _Unknown    # a function's return value is not followed
            if f == "globals":
                out = _union(out, [self.globals_dict()])
                continue
            if f not in _BUILTINS.values() and f not in _TYPES.values():
                raise _Unknown
            out = _union(out, self._apply(self._each(node.args + [k.value for k in node.keywords], fn, env),
                                          lambda *v, f=f: f(*v[:n], **dict(zip(keys, v[n:])))))
            if out is _TOP:
                raise _Unknown
        return out

    def globals_dict(self):
        g = _Globals()
        for name, vals in self.consts.items():
            if vals is not _TOP and len(vals) == 1:
                g[name] = vals[0]
        return g

    # --- the fixpoint ---------------------------------------------------------------------------------
    def run(self) -> bool:
        """Compute every function's parameter and local values; False where the script mutates a value
        the analysis follows, or runs code that may rebind anything (then nothing is sliced)."""
        if self.opaque:
            return False
        for _ in range(60):
            before = self._state()
            self._calls()
            for name, fn in self.defs.items():
                self._locals(name, fn)
            self._attributes()
            if not self._mutations():
                return False
            if self._state() == before and not self._bottom_arguments():
                return True
        return False

    def _bottom_arguments(self) -> bool:
        """Once the values are stable: a call in code that runs (the module, or a function some call binds
        or that escaped) passing a value with no possible value found (a binding the analysis does not
        model) makes that parameter unknown; True when one did (the fixpoint goes on)."""
        grew = False
        for node in ast.walk(self.tree):
            if not isinstance(node, ast.Call):
                continue
            scope = self._callee_scope(node)
            if scope in self.defs and scope not in self.called and scope not in self.escaped:
                continue
            if (any(isinstance(x, ast.Starred) for x in node.args)
                    or any(k.arg is None for k in node.keywords)):
                continue   # its callees' parameters are unknown already
            if isinstance(node.func, ast.Attribute):
                keys = [k for k in self.defs if k.endswith("." + node.func.attr)]
                shift = 1
            else:
                funcs = self._eval_in(node.func, scope)
                refs = [] if funcs is _TOP else [f.name for f in funcs if isinstance(f, _Ref)]
                keys = [r for r in refs if r in self.defs] + [f"{r}.__init__" for r in refs
                                                              if f"{r}.__init__" in self.defs]
                shift = None
            for key in keys:
                a = self.defs[key].args
                names = [p.arg for p in a.posonlyargs + a.args][(1 if shift or "." in key else 0):]
                pairs = list(zip(names, node.args)) + [(k.arg, k.value) for k in node.keywords]
                for p, x in pairs:
                    if self._eval_in(x, scope) == [] and self.params[key].get(p) is not _TOP:
                        self.params[key][p] = _TOP
                        grew = True
        return grew

    def _state(self) -> str:
        return repr((self.params, self.locals, sorted(self.escaped), self.attrs,
                     {k: v for k, v in self.consts.items() if v is _TOP}))

    def _callee_scope(self, node):
        """The analysed function whose own scope holds ``node`` (None: module level or a nested scope)."""
        p = self.parents.get(node)
        while p is not None:
            if isinstance(p, ast.Lambda | ast.ClassDef):
                return "nested"
            if isinstance(p, ast.FunctionDef | ast.AsyncFunctionDef):
                up = self.parents.get(p)
                if up is self.tree and p.name in self.defs:
                    return p.name
                if (isinstance(up, ast.ClassDef) and self.parents.get(up) is self.tree
                        and f"{up.name}.{p.name}" in self.defs):
                    return f"{up.name}.{p.name}"
                return "nested"
            p = self.parents.get(p)
        return None

    def method_names(self) -> set:
        return {k.split(".", 1)[1] for k in self.defs if "." in k}

    def _env(self, scope):
        if scope is None:
            return None, self.consts
        if scope == "nested":
            return "nested", {}
        return scope, {**self.params[scope], **self.locals[scope]}

    def _eval_in(self, node, scope):
        fn, env = self._env(scope)
        if fn == "nested":    # a nested scope: its own names unknown, the module's known
            names = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}
            if names - set(self.consts) - set(_BUILTINS) - set(_TYPES) - {"globals", "None", "True", "False"}:
                return _TOP
            return self._eval(node, None, self.consts)
        return self._eval(node, fn, env)

    def _calls(self) -> None:
        methods = self.method_names()
        for node in ast.walk(self.tree):
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
                self._escapes(node)
            if (isinstance(node, ast.Attribute) and node.attr in methods
                    and not (isinstance(self.parents.get(node), ast.Call)
                             and self.parents[node].func is node)):
                self.escaped |= {k for k in self.defs if k.endswith("." + node.attr)}   # a bound method
            if not isinstance(node, ast.Call):
                continue
            scope = self._callee_scope(node)
            if isinstance(node.func, ast.Attribute):     # obj.m(...): every method m of the script's classes
                if node.func.attr not in methods:
                    continue
                keys = [k for k in self.defs if k.endswith("." + node.func.attr)]
                recv = self._eval_in(node.func.value, scope)
                if self.dynamic or (recv is not _TOP and any(isinstance(v, _Ref) for v in recv)):
                    self.escaped |= set(keys)    # Class.m(obj, ...): unbound, its first argument not self
                self._bind_call(node, scope, keys, skip_self=True)
                continue
            funcs = self._eval_in(node.func, scope)
            if funcs is _TOP:
                continue
            refs = [f.name for f in funcs if isinstance(f, _Ref)]
            if any(r in self.classes and f"{r}.__init__" not in self.defs and self.classes[r].bases
                   for r in refs):   # an inherited __init__: which one, the analysis does not resolve
                self.escaped |= {k for k in self.defs if k.endswith(".__init__")}
            self._bind_call(node, scope, [r for r in refs if r in self.defs], skip_self=False)
            self._bind_call(node, scope, [f"{r}.__init__" for r in refs if f"{r}.__init__" in self.defs],
                            skip_self=True)
        for k in self.escaped:
            for p in self.defs[k].args.args + self.defs[k].args.kwonlyargs:
                self.params[k][p.arg] = _TOP

    def _bind_call(self, node, scope, keys, skip_self) -> None:
        """Add the values call ``node`` passes to the parameters of each function ``keys``."""
        for key in keys:
            self.called.add(key)
            fn = self.defs[key]
            a = fn.args
            names = [p.arg for p in a.posonlyargs + a.args]
            if skip_self:
                if names:
                    self.params[key][names[0]] = _TOP
                names = names[1:]
            starred = (any(isinstance(x, ast.Starred) for x in node.args)
                       or any(k.arg is None for k in node.keywords) or a.vararg or a.kwarg
                       or a.kwonlyargs or len(node.args) > len(names))
            got: dict = {}
            if not starred:
                for p, x in zip(names, node.args):
                    got[p] = self._eval_in(x, scope)
                for k in node.keywords:
                    if k.arg not in names:
                        starred = True
                        break
                    got[k.arg] = self._eval_in(k.value, scope)
                defaults = dict(zip(names[len(names) - len(a.defaults):], a.defaults))
                for p in names:
                    if p not in got:
                        got[p] = self._eval(defaults[p], None, self.consts) if p in defaults else _TOP
            for p in names + [x.arg for x in a.kwonlyargs]:
                self.params[key][p] = _union(self.params[key].get(p, []),
                                             _TOP if starred else got.get(p, _TOP))

    def _escapes(self, name_node) -> None:
        """Mark the functions a name's value may hold as escaped, unless it is called, or passed straight
        to a call of the analysed functions only."""
        parent = self.parents.get(name_node)
        if isinstance(parent, ast.Call) and parent.func is name_node:
            return
        scope = self._callee_scope(name_node)
        vals = self._eval_in(name_node, scope)
        refs = [] if vals is _TOP else [v for v in vals if isinstance(v, _Ref)]
        if not refs:
            return
        if isinstance(parent, ast.keyword):
            parent = self.parents.get(parent)
        elif not (isinstance(parent, ast.Call) and name_node in parent.args):
            parent = None
        ok = False
        if isinstance(parent, ast.Call):
            funcs = self._eval_in(parent.func, scope)
            ok = funcs is not _TOP and all(isinstance(f, _Ref) for f in funcs)
        if not ok:
            for r in refs:
                self.escaped |= {r.name} & set(self.defs)
                self.escaped |= {k for k in self.defs if k.startswith(r.name + ".")}   # a class: any call

    def _locals(self, name, fn) -> None:
        env = {**self.params[name], **self.locals[name]}
        for node in _scope_nodes(fn):
            if isinstance(node, ast.Assign):
                vals = self._eval(node.value, name, env)
                for t in node.targets:
                    self._bind(t, vals, env)
            elif isinstance(node, ast.AnnAssign) and node.value is not None:
                self._bind(node.target, self._eval(node.value, name, env), env)
            elif isinstance(node, ast.NamedExpr):
                self._bind(node.target, self._eval(node.value, name, env), env)
            elif isinstance(node, ast.For | ast.AsyncFor | ast.comprehension):
                it = self._eval(node.iter, name, env)
                try:
                    items = _TOP if it is _TOP else [x for v in it for x in list(v)[:_CAP + 1]]
                except TypeError:
                    items = _TOP
                self._bind(node.target, _TOP if items is _TOP or len(items) > _CAP else items, env)
            elif isinstance(node, ast.AugAssign):
                self._bind(node.target, _TOP, env)
            elif isinstance(node, ast.With | ast.AsyncWith):
                for i in node.items:
                    if i.optional_vars is not None:
                        self._bind(i.optional_vars, _TOP, env)
            elif isinstance(node, ast.ExceptHandler) and node.name:
                env[node.name] = _TOP
            elif isinstance(node, ast.Import | ast.ImportFrom | ast.Global | ast.Nonlocal | ast.Delete):
                for t in self._targets(node) if isinstance(node, ast.Import | ast.ImportFrom) else []:
                    env[t.id] = _TOP
                for n in getattr(node, "names", []):
                    if isinstance(n, str):
                        env[n] = _TOP
                for t in getattr(node, "targets", []):
                    for n in ast.walk(t):
                        if isinstance(n, ast.Name):
                            env[n.id] = _TOP
        self.locals[name] = {k: v for k, v in env.items() if k not in self.params[name] or k in
                             self._rebound(fn)}

    @staticmethod
    def _rebound(fn) -> set:
        return {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}

    def _attributes(self) -> None:
        """The values each attribute name can take: the union of every store to ``.name`` in the script
        (any object's: stores are matched by name), and of a class-level assignment in the script's
        classes; unknown for a store the analysis cannot evaluate, and for a name never stored."""
        if self.dynamic:
            return
        for node in ast.walk(self.tree):
            if isinstance(node, ast.Assign):
                scope = self._callee_scope(node)
                vals = self._eval_in(node.value, scope)
                for t in node.targets:
                    self._attr_bind(t, vals)
            elif isinstance(node, ast.AugAssign | ast.AnnAssign | ast.For | ast.AsyncFor | ast.With
                            | ast.AsyncWith | ast.Delete | ast.NamedExpr):
                for t in (node.targets if isinstance(node, ast.Delete) else self._targets(node)
                          if not isinstance(node, ast.NamedExpr) else [node.target]):
                    for n in ast.walk(t):
                        if isinstance(n, ast.Attribute):
                            self.attrs[n.attr] = _TOP
        for node in ast.walk(self.tree):   # setattr(x, "name", …), delattr(x, "name")
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ("setattr", "delattr") and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant)):
                self.attrs[node.args[1].value] = _TOP
        for cls in self.classes.values():
            for stmt in cls.body:
                if isinstance(stmt, ast.Assign):
                    vals = self._eval(stmt.value, None, self.consts)
                    for t in stmt.targets:
                        for n in ast.walk(t):
                            if isinstance(n, ast.Name):
                                self.attrs[n.id] = _union(self.attrs.get(n.id, []), _TOP if len(
                                    stmt.targets) > 1 or not isinstance(t, ast.Name) else vals)
        for a in self.forced_attrs:
            self.attrs[a] = _TOP

    def _attr_bind(self, target, vals) -> None:
        if isinstance(target, ast.Attribute):
            self.attrs[target.attr] = _union(self.attrs.get(target.attr, []), vals)
        elif isinstance(target, ast.Tuple | ast.List):
            parts: list = [[] for _ in target.elts]
            if vals is _TOP or any(isinstance(e, ast.Starred) for e in target.elts):
                parts = [_TOP] * len(target.elts)
            else:
                for v in vals:
                    try:
                        items = list(v)
                    except TypeError:
                        items = []
                    for i in range(len(parts)):
                        parts[i] = _union(parts[i], [items[i]] if len(items) == len(parts) else _TOP)
            for e, part in zip(target.elts, parts):
                self._attr_bind(e.value if isinstance(e, ast.Starred) else e, part)
        elif isinstance(target, ast.Starred):
            self._attr_bind(target.value, _TOP)

    def _mutations(self) -> bool:
        """Unknown: each fresh container the script mutates (a local, an attribute or a module constant
        every assignment of which builds a new one); False when it mutates any other value the analysis
        follows."""
        for node in ast.walk(self.tree):
            base = None
            if isinstance(node, ast.Subscript | ast.Attribute) and isinstance(node.ctx, ast.Store | ast.Del):
                base = node.value
            elif isinstance(node, ast.AugAssign):
                base = node.target
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr in _MUTATORS):
                base = node.func.value
            first = None
            while isinstance(base, ast.Subscript | ast.Attribute):
                first, base = base, base.value
            if isinstance(first, ast.Attribute) and not self.dynamic:   # x.attr…: attr's value mutated
                vals = self.attrs.get(first.attr, _TOP)
                if vals is not _TOP and any(isinstance(v, list | dict | set) for v in vals):
                    if not self._fresh_attr(first.attr):
                        return False
                    self.forced_attrs.add(first.attr)
                    self.attrs[first.attr] = _TOP
            if not isinstance(base, ast.Name):
                continue
            scope = self._callee_scope(node)
            vals = self._eval_in(base, scope)
            if vals is _TOP or not any(isinstance(v, list | dict | set) for v in vals):
                continue
            if scope in self.defs and base.id in self.local_names[scope]:
                if not self._fresh(self.defs[scope], base.id):
                    return False
                self.forced_top[scope].add(base.id)
                self.locals[scope][base.id] = _TOP
            elif self._fresh_global(base.id):
                self.consts[base.id] = _TOP
            else:
                return False
        return True

    def _fresh_attr(self, attr) -> bool:
        """Every store to ``.attr`` in the script builds a new container."""
        for node in ast.walk(self.tree):
            if not isinstance(node, ast.Assign):
                continue
            for t in node.targets:
                pairs = ([(t, node.value)] if isinstance(t, ast.Attribute) else
                         list(zip(t.elts, node.value.elts)) if isinstance(t, ast.Tuple)
                         and isinstance(node.value, ast.Tuple) and len(t.elts) == len(node.value.elts)
                         else [(n, None) for n in ast.walk(t) if isinstance(n, ast.Attribute)])
                for target, value in pairs:
                    if isinstance(target, ast.Attribute) and target.attr == attr and not _is_fresh(value):
                        return False
        return True

    def _fresh_global(self, name) -> bool:
        """``name`` is a module constant assigned once, to a new container, and never from a function."""
        stores = [node for node in self.tree.body if isinstance(node, ast.Assign)
                  and any(isinstance(t, ast.Name) and t.id == name for t in node.targets)]
        return (len(stores) == 1 and len(stores[0].targets) == 1 and _is_fresh(stores[0].value)
                and not any(isinstance(n, ast.Global) and name in n.names for n in ast.walk(self.tree)))

    @staticmethod
    def _fresh(fn, name) -> bool:
        """Every assignment to ``name`` in ``fn`` builds a new container (a display, a comprehension,
        list()/dict()/set()), and it is no parameter."""
        if name in {a.arg for a in fn.args.args + fn.args.posonlyargs + fn.args.kwonlyargs}:
            return False
        seen = False
        for node in _scope_nodes(fn):
            targets = (node.targets if isinstance(node, ast.Assign) else
                       [node.target] if isinstance(node, ast.AnnAssign | ast.For | ast.NamedExpr) else [])
            for t in targets:
                names = [t] if isinstance(t, ast.Name) else (list(t.elts) if isinstance(t, ast.Tuple) else [])
                for i, n in enumerate(names):
                    if not (isinstance(n, ast.Name) and n.id == name):
                        continue
                    seen = True
                    value = node.value if not isinstance(node, ast.For) else None
                    if isinstance(t, ast.Tuple):
                        value = value.elts[i] if isinstance(value, ast.Tuple) else None
                    if not _is_fresh(value):
                        return False
        return seen

    # --- what goes ------------------------------------------------------------------------------------
    def decided(self, fn_name, node):
        """True/False when the test of ``if`` ``node`` (in function ``fn_name``) is so for every value it
        can take; for a ``for``, False when every iterable is empty; else None."""
        env = {**self.params[fn_name], **self.locals[fn_name]}
        if isinstance(node, ast.If):
            vals = self._eval(node.test, fn_name, env)
            if vals is _TOP or not vals:
                return None
            truth = {bool(v) for v in vals}
            return truth.pop() if len(truth) == 1 else None
        vals = self._eval(node.iter, fn_name, env)
        if vals is _TOP or not vals:
            return None
        try:
            return False if all(len(list(v)) == 0 for v in vals) else None
        except TypeError:
            return None


def _is_fresh(value) -> bool:
    """``value`` builds a new container: a display, a comprehension, list()/dict()/set()."""
    return (isinstance(value, ast.List | ast.Dict | ast.Set | ast.ListComp | ast.DictComp | ast.SetComp)
            or (isinstance(value, ast.Call) and isinstance(value.func, ast.Name)
                and value.func.id in _FRESH_CALLS))


def _splice(value):
    if not isinstance(value, list | tuple | str | range):
        raise _Unknown
    return tuple(value)


def _index(v, i):
    if isinstance(v, _Globals) and i not in v:
        raise _Unknown
    if not isinstance(v, list | tuple | dict | str | range):
        raise _Unknown
    return v[i]


def _compare(op, a, b):
    return {ast.Eq: lambda: a == b, ast.NotEq: lambda: a != b, ast.Lt: lambda: a < b, ast.LtE: lambda: a <= b,
            ast.Gt: lambda: a > b, ast.GtE: lambda: a >= b, ast.Is: lambda: a is b,
            ast.IsNot: lambda: a is not b, ast.In: lambda: a in b, ast.NotIn: lambda: a not in b}[type(op)]()


_BINOPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
           ast.Div: lambda a, b: a / b, ast.FloorDiv: lambda a, b: a // b, ast.Mod: lambda a, b: a % b,
           ast.Pow: lambda a, b: a ** b}


def _string_rows(text: str) -> set:
    """Rows inside (or ending) a multi-line string token: their indentation is the string's."""
    rows, fstrings = set(), []
    f_start, f_end = getattr(tokenize, "FSTRING_START", None), getattr(tokenize, "FSTRING_END", None)
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.STRING and tok.end[0] > tok.start[0]:
            rows.update(range(tok.start[0], tok.end[0] + 1))
        elif f_start is not None and tok.type == f_start:   # Python >= 3.12 splits an f-string in tokens
            fstrings.append(tok.start[0])
        elif f_end is not None and tok.type == f_end and fstrings:
            first = fstrings.pop()
            if tok.end[0] > first:
                rows.update(range(first, tok.end[0] + 1))
    return rows


def _edits(analysis, lines, string_rows):
    """(first row, last row, kept rows, dedent) of each sliced statement, outermost first."""
    out = []
    for name, fn in analysis.defs.items():
        for node in _scope_nodes(fn):
            if not isinstance(node, ast.If | ast.For) or _is_elif(node, lines):
                continue
            if isinstance(node, ast.For) and not isinstance(node.target, ast.Name | ast.Tuple):
                continue
            got = analysis.decided(name, node)
            if got is None:
                continue
            keep = node.body if got else node.orelse
            if keep and isinstance(node, ast.If) and _is_elif(keep[0], lines):
                continue
            block = _block_of(node, analysis)
            if not keep and (block is None or len(block) == 1):
                continue
            rows = set(range(keep[0].lineno, keep[-1].end_lineno + 1)) if keep else set()
            span = range(min([node.lineno] + [d.lineno for d in getattr(node, "decorator_list", [])]),
                         node.end_lineno + 1)
            if rows & string_rows:
                continue
            after = []   # what follows a kept block that always returns or raises: never reached
            if keep and isinstance(keep[-1], ast.Return | ast.Raise) and block is not None:
                after = [s for s in block if s.lineno > node.end_lineno]
            dedent = (keep[0].col_offset - node.col_offset) if keep else 0
            out.append((span.start, span.stop - 1, rows, dedent, after))
    return out


def _is_elif(node, lines) -> bool:
    return isinstance(node, ast.If) and lines[node.lineno - 1].lstrip().startswith("elif")


def _block_of(node, analysis):
    parent = analysis.parents.get(node)
    for field in ("body", "orelse", "finalbody"):
        block = getattr(parent, field, None)
        if isinstance(block, list) and node in block:
            return block
    return None


def prune(text: str) -> str:
    """``text`` (a script's whole code) without what its fixed numbers never reach (the module docstring);
    as it is where the script mutates a value the analysis follows."""
    tree = ast.parse(text)
    lines = text.splitlines()
    analysis = _Analysis(tree)
    if not analysis.run():
        return text
    edits = _edits(analysis, lines, _string_rows(text))
    drop, dedent = set(), {}
    taken: list = []
    for first, last, keep, d, after in sorted(edits, key=lambda e: (e[0], -e[1])):
        if any(a <= first and last <= b for a, b in taken):
            continue   # inside a statement already sliced: its own slice is decided again on the next pass
        taken.append((first, last))
        for row in range(first, last + 1):
            if row in keep:
                dedent[row] = dedent.get(row, 0) + d
            else:
                drop.add(row)
        for s in after:
            drop.update(range(s.lineno, s.end_lineno + 1))
    if not drop:
        return text
    out = []
    for row, line in enumerate(lines, 1):
        if row in drop:
            continue
        d = dedent.get(row, 0)
        out.append(line[d:] if line[:d].strip() == "" else line)
    return prune("\n".join(out) + ("\n" if text.endswith("\n") else ""))

