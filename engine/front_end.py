"""Taichi's front end, quickened: the same kernels and texts, built sooner.

Taichi's front end runs on every kernel at every start, also when the kernel then comes from the
offline cache. :func:`install` (run when the engine is imported, and again by
``engine.runtime.init``; idempotent) replaces some of its pieces with quicker ones that give the
same text or answer (tests/test_front_end.py): memoised source positions and source lines, a
quicker text wrapper, a direct class check, and :mod:`engine.quick_ops`' vector reductions.
:class:`KeptTexts` keeps the source-position texts and source lines from one start to the next,
beside Taichi's offline cache. (Private Taichi APIs: where one is not there, it is left alone.)
"""
from __future__ import annotations

import atexit
import contextlib
import linecache
import marshal
import os
import sys
import textwrap
import types
import weakref

import taichi as ti


def install() -> None:
    """Taichi's front end runs on every kernel at every start, also when the kernel then comes
    from the offline cache, and spends much of it on text only a failing kernel shows. Each
    piece below gives the same text or answer as Taichi's own, sooner (tests/test_front_end.py).
    (Private Taichi APIs: where one is not there, it is left alone.)

    Taichi formats a node's source position (file, line, the line with a caret under the node,
    wrapped by ``textwrap``) for every node of every kernel it builds, and again for a ``ti.func``
    each time it is inlined: ~40,000 strings for sparks' first frame (kept, with the source lines
    below: warm start 3.5 → 2.9 s). The string is a function of the node's place in its source,
    so it is kept and reused: the same text, built once — and kept for the next start too
    (:class:`KeptTexts`: sparks' ~8,800 texts took ~70 ms to build, ~6 ms to read back)."""
    try:
        from taichi.lang.ast import ast_transformer_utils as atu

        ctx_cls = atu.ASTTransformerContext
        original = ctx_cls.get_pos_info
    except (ImportError, AttributeError):  # pragma: no cover - another Taichi version
        return
    if getattr(original, "memoized", False):
        return
    memo = {}

    def get_pos_info(self, node):
        try:
            key = (self.file, self.lineno_offset, self.indent, self.func.func.__name__, type(node),
                   node.lineno, node.end_lineno, node.col_offset, node.end_col_offset)
        except AttributeError:  # pragma: no cover
            return original(self, node)
        text = memo.get(key)
        if text is None:
            # (and from one start to the next: ~8,800 distinct texts, ~70 ms of sparks' warm start)
            text = KEPT_TEXTS.get(key)
            if text is None:
                text = original(self, node)
                KEPT_TEXTS.put(key, text)
            memo[key] = text
        return text

    get_pos_info.memoized, get_pos_info.original = True, original
    ctx_cls.get_pos_info = get_pos_info
    # the text wraps each source line and caret line at 80 columns (``textwrap``, ~26,000 calls
    # for sparks' first frame, a third of them distinct): a line that fits comes back as it is
    if getattr(atu, "TextWrapper", None) is textwrap.TextWrapper:
        atu.TextWrapper = _QuickWrapper
    try:
        from taichi.lang import kernel_impl
    except ImportError:  # pragma: no cover
        return
    # and each function's source is re-filled line by line (``textwrap.fill``, width 9999: tabs
    # expanded, trailing blanks dropped) before it is parsed, ~7,800 lines for sparks' first frame
    if getattr(kernel_impl, "textwrap", None) is textwrap:
        shim = types.ModuleType("textwrap")
        shim.__dict__.update(vars(textwrap))
        shim.fill = _quick_fill
        kernel_impl.textwrap = shim
    # and each kernel or ti.func, as it is decorated, asks whether it is defined in a class by
    # reading its frame's source line through ``inspect.getframeinfo``, whose file lookup scans
    # every loaded module (~0.6 ms a decoration, ~0.1 s of a start): read the line directly
    taichis = getattr(kernel_impl, "_inside_class", None)
    if taichis not in (None, _inside_class) and hasattr(kernel_impl, "_KERNEL_CLASS_STACKFRAME_STMT_RES"):
        _inside_class.taichis = taichis  # (kept for tests/test_front_end.py)
        kernel_impl._inside_class = _inside_class
    # and a function's source lines and file, looked up (inspect: tokenize, getmodule) each
    # time a kernel is built or a ti.func inlined, once a function (weakly held: a scene's
    # closures go with it)
    # (the lines kept from one start to the next too: inspect tokenizes the file from the
    # function's first line to find its end, ~0.5 ms a function, ~100 functions for sparks)
    for name in ("getsourcelines", "getsourcefile"):
        found = getattr(kernel_impl, name, None)
        if found is not None:
            setattr(kernel_impl, name, _memoized_by_function(_kept_lines(found) if name == "getsourcelines"
                                                             else found))
    # and a vector's dot, sum, norm, cross… built directly instead of inlined as functions, each
    # parsed and transformed at every call (engine.quick_ops: the same operations in the same order)
    from . import quick_ops

    quick_ops.install()


class _QuickWrapper(textwrap.TextWrapper):
    """``textwrap.TextWrapper`` for Taichi's front end: the same lines, quicker. A printable line
    that fits the width (less one trailing newline, as ``inspect.getsourcelines`` gives: wrapping
    turns it into a trailing blank) is one line as it is, less trailing spaces, none if it is all
    spaces — what ``wrap`` returns for it (tests/test_front_end.py compares the two); any other
    text is wrapped by ``TextWrapper`` once and kept (Taichi builds a wrapper per call)."""

    _kept: dict = {}

    def wrap(self, text):
        body = text[:-1] if text.endswith("\n") else text
        if len(text) <= self.width and body.isprintable():
            line = body.rstrip(" ")
            return [line] if line else []
        key = (self.width, self.tabsize, text)
        got = self._kept.get(key)
        if got is None:
            got = self._kept[key] = super().wrap(text)
        return list(got)


def _quick_fill(text, width=70, **kwargs):
    """``textwrap.fill`` by ``_QuickWrapper`` (its options width and tabsize; any other goes to
    ``textwrap.fill`` itself)."""
    if set(kwargs) <= {"tabsize"}:
        return "\n".join(_QuickWrapper(width=width, **kwargs).wrap(text))
    return textwrap.fill(text, width=width, **kwargs)


def _inside_class(level_of_class_stackframe):
    """Taichi's test of whether a kernel or ti.func is being defined in a class body: whether the
    statement running ``level_of_class_stackframe`` frames up begins ``class`` or
    ``@…data_oriented`` (Taichi's own patterns), its line read through ``linecache``."""
    from taichi.lang import kernel_impl

    try:
        frame = sys._getframe(level_of_class_stackframe)
        line = linecache.getline(frame.f_code.co_filename, frame.f_lineno).strip()
    except Exception:  # (as Taichi's: no frame or no source, not a class)
        return False
    return any(p.match(line) for p in kernel_impl._KERNEL_CLASS_STACKFRAME_STMT_RES)


def _memoized_by_function(look_up):
    kept = weakref.WeakKeyDictionary()

    def memoized(fn):
        try:
            got = kept.get(fn)
        except TypeError:  # pragma: no cover - not weakly referable
            return look_up(fn)
        if got is None:
            got = kept[fn] = look_up(fn)
        return got

    return memoized


def _kept_lines(look_up):
    """``getsourcelines`` (``look_up``) through :data:`KEPT_TEXTS`: a function's source lines and
    first line number, kept with its file's texts. What inspect returns is a function of the
    file's text (which :class:`KeptTexts` checks by its digest, read through ``linecache`` as
    inspect reads it, at every look-up: an edited and reloaded module gets its new lines) and of
    where the unwrapped function starts (inspect follows ``__wrapped__``; so does the key)."""
    import inspect

    def lines(fn):
        try:
            code = inspect.unwrap(fn).__code__
        except (AttributeError, ValueError):
            return look_up(fn)
        if not os.path.isabs(code.co_filename):
            return look_up(fn)
        where = ("<lines>", code.co_firstlineno, code.co_name)
        got = KEPT_TEXTS.get_at(code.co_filename, where, check=True)
        if got is None:
            src, start = look_up(fn)
            got = (list(src), int(start))
            KEPT_TEXTS.put_at(code.co_filename, where, got)
        return got

    return lines


class KeptTexts:
    """Taichi's source-position texts and functions' source lines (see :func:`install`)
    kept from one start to the next, beside the kernels in Taichi's offline cache: one small file
    per source file, read when a kernel from that source is first built (a scene reads those of
    the ~20 files its kernels come from). What is kept is a function of the source file's text,
    so each file's entries are kept with a digest of that text, read through ``linecache`` as
    inspect reads it, and dropped when it differs (an edit, whatever it does to the file's size
    or time); all of them when Taichi's or Python's version or this format changes. Source lines
    are looked up with ``check``: the file's text is checked again (``linecache.checkcache``), so
    an edited and reloaded module gets its new lines in the same process. Nothing is kept
    without an offline cache (a host may run Taichi without one), for sources that are not files
    at absolute paths, or past ``MAX_TEXTS`` a file. Read with ``marshal`` (strings, ints,
    tuples and lists only); written whole under a temporary name and renamed, so a reader sees
    the old file or the new one, never a part."""

    FOLDER = "particles-source-texts"
    FORMAT = 3
    MAX_TEXTS = 50_000

    def __init__(self, folder=None):
        self.folder = folder  # None: Taichi's offline cache folder, looked up at first use
        # source file → [digest of its text, {key without the file: value}, changed, its lines]
        self.files = {}

    @property
    def changed(self) -> bool:
        return any(entry[2] for entry in self.files.values() if entry is not None)

    def _where(self):
        if self.folder is None:
            try:
                if ti.lang.impl.get_runtime().prog is None:
                    return ""  # Taichi not started yet: its cache folder is not known
                cfg = ti.lang.impl.current_cfg()
                self.folder = (os.path.abspath(os.path.join(cfg.offline_cache_file_path, self.FOLDER))
                               if cfg.offline_cache else "")
            except Exception:  # pragma: no cover
                return ""
        return self.folder

    def forget_folder(self) -> None:
        """Look the cache folder up again (Taichi reset: the next program may keep another)."""
        self.folder = None

    def _path(self, file) -> str:
        import hashlib

        name = hashlib.sha1(file.encode("utf-8", "surrogatepass")).hexdigest()[:20]
        return os.path.join(self.folder, name + ".marshal")

    @staticmethod
    def _header():
        return (KeptTexts.FORMAT, tuple(ti.__version__), tuple(sys.version_info[:2]))

    def _entry(self, file, check=False):
        """The kept entry of ``file`` (read at first use; None: not a file, or no cache);
        ``check``: compare the file's text (linecache, re-stat'ed) with the entry's again."""
        entry = self.files.get(file)
        if entry is None and file in self.files:
            return None
        if entry is not None and not check:
            return entry
        folder = self._where()
        if self.folder is None:  # (not known before Taichi starts: asked again later)
            return None
        if not folder or not isinstance(file, str) or not os.path.isabs(file):
            self.files[file] = None
            return None
        if check:
            linecache.checkcache(file)
        lines = linecache.getlines(file)
        if entry is not None and entry[3] is lines:
            return entry
        if not lines:
            self.files[file] = None
            return None
        import hashlib

        digest = hashlib.sha1("".join(lines).encode("utf-8", "surrogatepass")).hexdigest()
        if entry is not None and entry[0] == digest:
            entry[3] = lines
            return entry
        entry = [digest, {}, False, lines]
        try:
            with open(self._path(file), "rb") as f:
                header, name, kept_digest, texts = marshal.loads(f.read())  # (load(f): piecemeal, 6x slower)
            if header == self._header() and name == file and kept_digest == digest and isinstance(texts, dict):
                entry[1] = texts
        except Exception:  # missing, unreadable or not ours: start empty
            pass
        self.files[file] = entry
        return entry

    @staticmethod
    def _within(key):
        """get_pos_info's key less its file, the node's type by name (what marshal can keep)."""
        return key[1:4] + (key[4].__name__,) + key[5:]

    def get(self, key):
        """The kept text for get_pos_info's ``key`` (file, line offset, indent, function name,
        node type, node lines and columns), or None."""
        return self.get_at(key[0], self._within(key))

    def put(self, key, text) -> None:
        self.put_at(key[0], self._within(key), text)

    def get_at(self, file, where, check=False):
        """What is kept for source ``file`` under ``where`` (a tuple marshal can write), or None."""
        entry = self._entry(file, check)
        return None if entry is None else entry[1].get(where)

    def put_at(self, file, where, value) -> None:
        entry = self._entry(file)
        if entry is not None and len(entry[1]) < self.MAX_TEXTS:
            entry[1][where] = value
            entry[2] = True

    def save(self) -> None:
        """Write the entries of every file this process added to (at exit)."""
        import tempfile

        for file, entry in list(self.files.items()):
            if entry is None or not entry[2]:
                continue
            entry[2] = False
            if not self._where():
                continue
            tmp = None
            try:
                os.makedirs(self.folder, exist_ok=True)
                fd, tmp = tempfile.mkstemp(dir=self.folder, suffix=".tmp")
                with os.fdopen(fd, "wb") as f:
                    f.write(marshal.dumps((self._header(), file, entry[0], entry[1])))
                os.replace(tmp, self._path(file))
            except Exception:  # a read-only or full cache folder: the next start recomputes them
                if tmp is not None:
                    with contextlib.suppress(OSError):
                        os.remove(tmp)


KEPT_TEXTS = KeptTexts()
atexit.register(KEPT_TEXTS.save)  # (also in a host that started Taichi itself; a no-op if nothing new)

# at import, not only at init: a kernel or ti.func at a module's top level is decorated (and asks
# whether it is in a class) when that module is imported, often before init (the command line
# imports the scene first)
install()
