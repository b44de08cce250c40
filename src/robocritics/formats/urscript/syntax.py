"""URScript source to a syntax tree: tokenizer and recursive-descent parser, both bounded.

Only the text is read here; nothing runs. The grammar is the statement and
expression language of URScript (the Universal Robots controller's script
language, as PolyScope, RoboDK and people write it): ``def``/``thread`` … ``end``,
``if``/``elif``/``else``, ``while``, ``for … in range(…)``, ``switch``/``case``/``default``,
``global``/``local`` assignments, ``return``/``break``/``continue``/``halt``,
``run``/``kill``/``join`` of threads, and expressions with numbers, strings,
``True``/``False``, lists ``[…]``, poses ``p[…]``, calls with keyword arguments and
indexing. PolyScope's node markers (``$ 3 "MoveJ"``) and ``#`` comments are skipped.

Bounds (a hostile file gets a typed error, never a hang or a Python RecursionError):
source size (:data:`MAX_SOURCE_CHARS`), tokens (:data:`MAX_TOKENS`), nesting of blocks and
expressions together (:data:`MAX_NESTING`), items of one list literal (:data:`MAX_LITERAL_ITEMS`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from ...errors import ProgramError

__all__ = [
    "URScriptError",
    "UnsupportedURScript",
    "parse",
    "Node",
    "MAX_NESTING",
    "MAX_TOKENS",
    "MAX_SOURCE_CHARS",
    "MAX_LITERAL_ITEMS",
]

MAX_SOURCE_CHARS = 2_000_000
MAX_TOKENS = 400_000
#: Blocks inside blocks and sub-expressions inside expressions, together (PolyScope exports nest ~10 deep).
MAX_NESTING = 64
MAX_LITERAL_ITEMS = 10_000


class URScriptError(ProgramError):
    """A URScript file that cannot be read or run: syntax, a bad value, a limit hit. ``line`` is 1-based."""

    def __init__(self, message: str, line: int = 0):
        super().__init__(message, line=line)
        Exception.__init__(self, f"line {line}: {message}" if line else message)  # URScript has no columns to name


class UnsupportedURScript(URScriptError):
    """A construct outside the subset robocritics interprets; ``construct`` names it, ``line`` says where."""

    def __init__(self, construct: str, line: int, why: str = ""):
        self.construct = construct
        super().__init__(f"unsupported URScript: {construct}" + (f" ({why})" if why else ""), line=line)


# --------------------------------------------------------------------------- tokens

_TOKEN = re.compile(
    r"""
    (?P<ws>[ \t\r\f]+|\\\n)
  | (?P<comment>\#[^\n]*)
  | (?P<nl>\n)
  | (?P<num>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z_0-9]*)
  | (?P<str>"(?:[^"\\\n]|\\.)*"|'(?:[^'\\\n]|\\.)*')
  | (?P<op>==|!=|<=|>=|\+=|-=|\*=|/=|[-+*/%<>=()\[\],:.$])
    """,
    re.VERBOSE,
)

KEYWORDS = frozenset(
    "def thread end if elif else while for in return break continue global local and or not xor "
    "True False halt run kill join switch case default enter_critical exit_critical pass".split()
)


@dataclass(frozen=True, slots=True)
class Token:
    kind: str  # num, str, name, kw, op, nl, eof
    text: str
    line: int


def tokenize(source: str) -> list[Token]:
    """Tokens of ``source``; newlines inside brackets are dropped, ``$ n "…"`` marker lines skipped."""
    if len(source) > MAX_SOURCE_CHARS:
        raise URScriptError(f"the file has {len(source):,} characters; the limit is {MAX_SOURCE_CHARS:,}")
    tokens: list[Token] = []
    line, depth, pos, n = 1, 0, 0, len(source)
    skip_marker = False
    while pos < n:
        m = _TOKEN.match(source, pos)
        if m is None:
            raise URScriptError(f"unexpected character {source[pos]!r}", line=line)
        kind, text = m.lastgroup, m.group()
        pos = m.end()
        if kind == "nl" or (kind == "ws" and text == "\\\n"):
            line += 1
            skip_marker = False
            if kind == "nl" and depth == 0 and tokens and tokens[-1].kind != "nl":
                tokens.append(Token("nl", "\n", line - 1))
            continue
        if kind in ("ws", "comment") or skip_marker:
            continue
        if kind == "op" and text == "$" and (not tokens or tokens[-1].kind == "nl"):
            skip_marker = True  # PolyScope's node marker: `$ 3 "MoveJ"` (and its optional flags)
            continue
        if kind == "name" and text in KEYWORDS:
            kind = "kw"
        elif kind == "op" and text in "([":
            depth += 1
        elif kind == "op" and text in ")]":
            depth = max(0, depth - 1)
        tokens.append(Token(kind, text, line))
        if len(tokens) > MAX_TOKENS:
            raise URScriptError(f"the file has more than {MAX_TOKENS:,} tokens", line=line)
    if tokens and tokens[-1].kind != "nl":
        tokens.append(Token("nl", "\n", line))
    tokens.append(Token("eof", "", line))
    return tokens


# --------------------------------------------------------------------------- tree


@dataclass(slots=True)
class Node:
    """One syntax-tree node: ``kind`` says what it is, ``line`` where; the other fields by kind.

    Expressions: ``num``/``str``/``bool`` (value), ``name`` (name), ``list``/``pose`` (items),
    ``unary`` (op, a), ``binary`` (op, a, b), ``call`` (name, items = args, kwargs), ``index`` (a, b).
    Statements: ``assign`` (a = target, b = value, scope, op), ``expr`` (a), ``if`` (branches, body = else),
    ``while`` (a = condition, body), ``for`` (name, items = range args, body), ``def``/``thread``
    (name, params, body), ``return`` (a), ``break``, ``continue``, ``halt``, ``switch`` (a, branches),
    ``run`` (name, a = the variable it is stored in), ``kill``/``join`` (no-ops), ``pass``.
    """

    kind: str
    line: int
    value: Any = None
    name: str = ""
    op: str = ""
    scope: str = ""
    a: Node | None = None
    b: Node | None = None
    items: list = field(default_factory=list)
    kwargs: dict = field(default_factory=dict)
    params: list = field(default_factory=list)  # [(name, default Node | None)]
    body: list = field(default_factory=list)
    branches: list = field(default_factory=list)  # [(condition or case value Node | None, body)]


_BINARY_PRECEDENCE = {
    "or": 1, "xor": 1, "and": 2,
    "==": 4, "!=": 4, "<": 4, ">": 4, "<=": 4, ">=": 4,
    "+": 5, "-": 5, "*": 6, "/": 6, "%": 6,
}  # fmt: skip
_BLOCK_END = {"end", "elif", "else", "case", "default"}


class _Parser:
    def __init__(self, tokens: list[Token]):
        self.tokens = tokens
        self.i = 0
        self.depth = 0

    # -- helpers
    @property
    def tok(self) -> Token:
        return self.tokens[self.i]

    def next(self) -> Token:
        t = self.tokens[self.i]
        if t.kind != "eof":
            self.i += 1
        return t

    def at(self, text: str) -> bool:
        t = self.tok
        return t.kind in ("op", "kw") and t.text == text

    def expect(self, text: str, what: str) -> Token:
        if not self.at(text):
            t = self.tok
            got = "end of line" if t.kind == "nl" else ("end of file" if t.kind == "eof" else repr(t.text))
            raise URScriptError(f"expected {text!r} {what}, got {got}", line=t.line)
        return self.next()

    def name(self, what: str) -> Token:
        t = self.tok
        if t.kind != "name":
            raise URScriptError(f"expected a name {what}, got {t.text or 'end of line'!r}", line=t.line)
        return self.next()

    def end_of_statement(self) -> None:
        t = self.tok
        if t.kind not in ("nl", "eof"):
            raise URScriptError(f"unexpected {t.text!r} after the statement", line=t.line)
        self.next()

    def enter(self, line: int) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise URScriptError(f"blocks and expressions nest more than {MAX_NESTING} deep", line=line)

    # -- statements
    def block(self, closers: set[str]) -> list[Node]:
        body: list[Node] = []
        while True:
            t = self.tok
            if t.kind == "nl":
                self.next()
                continue
            if t.kind == "eof":
                if closers:
                    raise URScriptError(f"the file ends inside a block; expected {' or '.join(sorted(closers))!r}", line=t.line)
                return body
            if t.kind == "kw" and t.text in closers:
                return body
            if t.kind == "kw" and t.text in _BLOCK_END:
                raise URScriptError(f"{t.text!r} without a block it belongs to", line=t.line)
            body.append(self.statement())

    def statement(self) -> Node:
        t = self.tok
        self.enter(t.line)
        try:
            if t.kind == "kw":
                handler = getattr(self, f"_stmt_{t.text}", None)
                if handler is not None:
                    return handler()
            node = self.simple_statement()
            self.end_of_statement()
            return node
        finally:
            self.depth -= 1

    def body_until_end(self, opener: Token) -> list[Node]:
        body = self.block({"end"})
        self.expect("end", f"closing the {opener.text!r} of line {opener.line}")
        self.end_of_statement()
        return body

    def _stmt_def(self) -> Node:
        start = self.next()
        name = self.name(f"after {start.text!r}")
        self.expect("(", "after the function name")
        params: list[tuple[str, Node | None]] = []
        while not self.at(")"):
            pname = self.name("of a parameter").text
            default = None
            if self.at("="):
                self.next()
                default = self.expression()
            params.append((pname, default))
            if not self.at(")"):
                self.expect(",", "between parameters")
        self.next()
        self.expect(":", f"after {start.text} {name.text}(...)")
        self.end_of_statement()
        return Node(start.text, start.line, name=name.text, params=params, body=self.body_until_end(start))

    _stmt_thread = _stmt_def

    def _stmt_if(self) -> Node:
        start = self.next()
        branches = []
        cond = self.expression()
        self.expect(":", "after the if condition")
        self.end_of_statement()
        body = self.block({"end", "elif", "else"})
        branches.append((cond, body))
        orelse: list[Node] = []
        while self.at("elif"):
            self.next()
            cond = self.expression()
            self.expect(":", "after the elif condition")
            self.end_of_statement()
            branches.append((cond, self.block({"end", "elif", "else"})))
        if self.at("else"):
            self.next()
            self.expect(":", "after else")
            self.end_of_statement()
            orelse = self.block({"end"})
        self.expect("end", f"closing the 'if' of line {start.line}")
        self.end_of_statement()
        return Node("if", start.line, branches=branches, body=orelse)

    def _stmt_while(self) -> Node:
        start = self.next()
        cond = self.expression()
        self.expect(":", "after the while condition")
        self.end_of_statement()
        return Node("while", start.line, a=cond, body=self.body_until_end(start))

    def _stmt_for(self) -> Node:
        start = self.next()
        var = self.name("after 'for'").text
        self.expect("in", "in 'for NAME in range(...)'")
        rng = self.tok
        if rng.text != "range":
            raise UnsupportedURScript(f"for loop over {rng.text!r} (only range(...))", start.line)
        self.next()
        self.expect("(", "after range")
        args = [self.expression()]
        while self.at(","):
            self.next()
            args.append(self.expression())
        self.expect(")", "closing range(")
        if len(args) > 3:
            raise URScriptError("range() takes at most 3 arguments", line=start.line)
        self.expect(":", "after the for header")
        self.end_of_statement()
        return Node("for", start.line, name=var, items=args, body=self.body_until_end(start))

    def _stmt_switch(self) -> Node:
        start = self.next()
        subject = self.expression()
        self.expect(":", "after the switch subject")
        self.end_of_statement()
        branches = []
        while self.tok.kind == "nl":
            self.next()
        while self.at("case") or self.at("default"):
            label = self.next()
            value = None if label.text == "default" else self.expression()
            self.expect(":", f"after {label.text}")
            self.end_of_statement()
            branches.append((value, self.block({"end", "case", "default"})))
        self.expect("end", f"closing the 'switch' of line {start.line}")
        self.end_of_statement()
        return Node("switch", start.line, a=subject, branches=branches)

    def _stmt_return(self) -> Node:
        start = self.next()
        value = None if self.tok.kind in ("nl", "eof") else self.expression()
        self.end_of_statement()
        return Node("return", start.line, a=value)

    def _simple_keyword(self) -> Node:
        start = self.next()
        self.end_of_statement()
        return Node(start.text, start.line)

    _stmt_break = _stmt_continue = _stmt_halt = _stmt_pass = _simple_keyword
    _stmt_enter_critical = _stmt_exit_critical = _simple_keyword

    def _stmt_kill(self) -> Node:
        start = self.next()
        self.expression()
        self.end_of_statement()
        return Node(start.text, start.line)

    _stmt_join = _stmt_kill

    def _stmt_run(self) -> Node:
        node = self.run_expression()
        self.end_of_statement()
        return node

    def run_expression(self) -> Node:
        start = self.next()
        name = self.name("after 'run'")
        self.expect("(", "after the thread name")
        self.expect(")", "(a thread takes no arguments)")
        return Node("run", start.line, name=name.text)

    def _stmt_global(self) -> Node:
        start = self.next()
        node = self.simple_statement()
        if node.kind != "assign" or node.a.kind != "name":
            raise URScriptError(f"{start.text} must be followed by NAME = value", line=start.line)
        node.scope = start.text
        self.end_of_statement()
        return node

    _stmt_local = _stmt_global

    def simple_statement(self) -> Node:
        t = self.tok
        if t.kind == "kw" and t.text not in ("not", "True", "False"):
            raise URScriptError(f"{t.text!r} cannot start a statement here", line=t.line)
        target = self.expression()
        if self.tok.kind == "op" and self.tok.text in ("=", "+=", "-=", "*=", "/="):
            op = self.next().text
            if target.kind not in ("name", "index"):
                raise URScriptError("only a variable or an element can be assigned to", line=t.line)
            value = self.run_expression() if self.at("run") else self.expression()
            return Node("assign", t.line, a=target, b=value, op=op)
        return Node("expr", t.line, a=target)

    # -- expressions
    def expression(self, min_precedence: int = 1) -> Node:
        t = self.tok
        self.enter(t.line)
        try:
            left = self.unary()
            while True:
                op = self.tok
                prec = _BINARY_PRECEDENCE.get(op.text) if op.kind in ("op", "kw") else None
                if prec is None or prec < min_precedence:
                    return left
                self.next()
                right = self.expression(prec + 1)
                left = Node("binary", op.line, op=op.text, a=left, b=right)
        finally:
            self.depth -= 1

    def unary(self) -> Node:
        t = self.tok
        if (t.kind == "op" and t.text in "-+") or (t.kind == "kw" and t.text == "not"):
            self.next()
            self.enter(t.line)
            try:
                operand = self.expression(3) if t.text == "not" else self.unary()
            finally:
                self.depth -= 1
            return Node("unary", t.line, op=t.text, a=operand)
        return self.postfix(self.atom())

    def postfix(self, node: Node) -> Node:
        while True:
            t = self.tok
            if t.kind == "op" and t.text == "[":
                self.next()
                index = self.expression()
                self.expect("]", "closing the index")
                node = Node("index", t.line, a=node, b=index)
            elif t.kind == "op" and t.text == "(" and node.kind == "name":
                node = self.call(node)
            elif t.kind == "op" and t.text == ".":
                raise UnsupportedURScript("struct field access (NAME.field)", t.line)
            else:
                return node

    def call(self, callee: Node) -> Node:
        self.next()
        args: list[Node] = []
        kwargs: dict[str, Node] = {}
        while not self.at(")"):
            t = self.tok
            if t.kind == "name" and self.tokens[self.i + 1].text == "=" and self.tokens[self.i + 1].kind == "op":
                self.next()
                self.next()
                kwargs[t.text] = self.expression()
            else:
                if kwargs:
                    raise URScriptError(f"positional argument after a keyword argument in {callee.name}()", line=t.line)
                args.append(self.expression())
            if len(args) + len(kwargs) > MAX_LITERAL_ITEMS:
                raise URScriptError(f"a call with more than {MAX_LITERAL_ITEMS:,} arguments", line=t.line)
            if not self.at(")"):
                self.expect(",", f"between the arguments of {callee.name}()")
        self.next()
        return Node("call", callee.line, name=callee.name, items=args, kwargs=kwargs)

    def sequence(self, start: Token, kind: str) -> Node:
        items: list[Node] = []
        while not self.at("]"):
            items.append(self.expression())
            if len(items) > MAX_LITERAL_ITEMS:
                raise URScriptError(f"a list literal with more than {MAX_LITERAL_ITEMS:,} items", line=start.line)
            if not self.at("]"):
                self.expect(",", "between list items")
        self.next()
        return Node(kind, start.line, items=items)

    def atom(self) -> Node:
        t = self.next()
        if t.kind == "num":
            text = t.text
            value: Any = float(text) if any(c in text for c in ".eE") else int(text)
            return Node("num", t.line, value=value)
        if t.kind == "str":
            return Node("str", t.line, value=t.text[1:-1])
        if t.kind == "kw" and t.text in ("True", "False"):
            return Node("bool", t.line, value=t.text == "True")
        if t.kind == "name":
            if t.text == "p" and self.at("["):
                return self.sequence(self.next(), "pose")
            return Node("name", t.line, name=t.text)
        if t.kind == "op" and t.text == "(":
            inner = self.expression()
            self.expect(")", f"closing the '(' of line {t.line}")
            return inner
        if t.kind == "op" and t.text == "[":
            return self.sequence(t, "list")
        if t.kind == "kw" and t.text == "run":
            self.i -= 1
            return self.run_expression()
        what = "end of line" if t.kind == "nl" else ("end of file" if t.kind == "eof" else repr(t.text))
        raise URScriptError(f"expected a value, got {what}", line=t.line)


def parse(source: str) -> list[Node]:
    """The statements of URScript ``source``; :class:`URScriptError` (with the line) for text that is not URScript."""
    return _Parser(tokenize(source)).block(set())
