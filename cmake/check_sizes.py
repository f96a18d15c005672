#!/usr/bin/env python3
"""Code size limits for libbtf (run by ctest as `sizes`; its scanner by `sizes_selftest`).

Limits, for every libbtf/**/*.h and *.cpp:
  - a function is at most 120 lines,
  - a class, struct or union is at most 400 lines,
  - a .cpp file is at most 900 lines.

What a length is: the number of lines from the first line of the definition (its first token
after the previous declaration: a `template <...>` header, attributes and the return type
included, comments before it not) through the line of its closing brace, both counted. So a
one-line function is 1 line, and `void f()\n{\n}` is 3. A file's length is its number of lines.

What counts as a function: every definition with a body outside another function's body:
free functions, member functions (defined in or out of their class), constructors (their
initialiser list belongs to them), operators, and lambdas assigned at namespace or class scope.
A lambda, local class or nested block inside a function is part of that function. Namespaces
and `extern "C"` blocks are not counted; enum bodies and braced initialisers are not functions.
Comments, string and character literals (raw strings included) and preprocessor lines are
blanked before braces are matched, so braces in them do not count.

Allow-list (ALLOW file): one entry per line, `#` starts a comment; `path:name` exempts the
function or class `name` (as this script reports it, e.g. `libbtf/x/y.cpp:ns::Foo::Bar`) in
that file, and `path` alone exempts the file's own length. An entry that matches no offender
fails the check too, so the list only shrinks.

Usage: check_sizes.py --source-dir <repo> [--allow <file>]   (exit 1 on any offender)
       check_sizes.py --self-test                           (the scanner's own test)
"""
import argparse
import io
import pathlib
import re
import sys
import tempfile

FUNCTION_LIMIT = 120
CLASS_LIMIT = 400
FILE_LIMIT = 900


class ParseError(Exception):
    pass


# ---------------------------------------------------------------------------------------------
# Blanking: comments, literals and preprocessor lines become spaces (newlines kept), so that
# line numbers stay and every remaining brace is code.

_RAW_PREFIX = re.compile(r'(?:u8|u|U|L)?R"([^()\\ \t\n]{0,16})\(')
_PREFIXED_QUOTE = re.compile(r'(?:u8|u|U|L)?["\']')


def _blank(s):
    return re.sub(r"[^\n]", " ", s)


def blank_non_code(text):
    out = []
    i, n = 0, len(text)
    at_line_start = True  # only whitespace since the last newline (a '#' here is a directive)
    while i < n:
        c = text[i]
        if c == "\n":
            out.append(c)
            i += 1
            at_line_start = True
            continue
        if c in " \t\r\f\v":
            out.append(c)
            i += 1
            continue
        if at_line_start and c == "#":  # preprocessor directive, with its continuation lines
            j = i
            while j < n and text[j] != "\n":
                if text[j] == "\\" and j + 1 < n and text[j + 1] == "\n":
                    j += 2
                    continue
                if text.startswith("/*", j):  # a block comment may run past the line
                    k = text.find("*/", j + 2)
                    j = n if k < 0 else k + 2
                    continue
                j += 1
            out.append(_blank(text[i:j]))
            i = j
            continue
        at_line_start = False
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(_blank(text[i:j]))
            i = j
            continue
        if text.startswith("/*", i):
            j = text.find("*/", i + 2)
            if j < 0:
                raise ParseError("unterminated comment")
            out.append(_blank(text[i:j + 2]))
            i = j + 2
            continue
        if c.isalpha() or c == "_":
            m = _RAW_PREFIX.match(text, i)
            if m and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
                end = text.find(")" + m.group(1) + '"', m.end())
                if end < 0:
                    raise ParseError("unterminated raw string")
                j = end + len(m.group(1)) + 2
                out.append(_blank(text[i:j]))
                i = j
                continue
            m = _PREFIXED_QUOTE.match(text, i)
            if m and m.end() - i > 1:  # u8"..", L'x': the prefix is kept, the literal blanked
                out.append(text[i:m.end() - 1])
                i = m.end() - 1
                continue
            j = i
            while j < n and (text[j].isalnum() or text[j] == "_"):
                j += 1
            out.append(text[i:j])
            i = j
            continue
        if c.isdigit() or (c == "." and i + 1 < n and text[i + 1].isdigit()):
            j = i  # a number, with digit separators (1'000) and exponents (1e+5, 0x1p-3)
            while j < n:
                if text[j].isalnum() or text[j] in "._":
                    j += 1
                elif text[j] == "'" and j + 1 < n and text[j + 1].isalnum():
                    j += 1
                elif text[j] in "+-" and text[j - 1] in "eEpP":
                    j += 1
                else:
                    break
            out.append(text[i:j])
            i = j
            continue
        if c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                if text[j] == "\\":
                    j += 1
                elif text[j] == "\n":
                    raise ParseError("newline in a literal")
                j += 1
            if j >= n:
                raise ParseError("unterminated literal")
            out.append(c + _blank(text[i + 1:j]) + c)
            i = j + 1
            continue
        out.append(c)
        i += 1
    return "".join(out)


# ---------------------------------------------------------------------------------------------
# Tokens and the structure of declarations.

_TOKEN = re.compile(r"""
    (?P<id>[A-Za-z_]\w*)
  | (?P<num>\.?\d[\w.']*)
  | (?P<str>"[ ]*"|'[ ]*')
  | (?P<op>::|->|\.\.\.|&&|\|\||<=>|<<=|>>=|[-+*/%^&|!=<>]=|<<|\#\#|[^\s\w])
""", re.VERBOSE)

_TRAILERS = {"const", "volatile", "noexcept", "override", "final", "mutable", "constexpr",
             "consteval", "static", "&", "&&", "throw"}
_NOT_A_DECLARATOR = {"alignas", "__attribute__", "decltype", "noexcept", "requires", "sizeof",
                     "alignof", "__declspec", "throw", "static_assert"}
_ACCESS = {"public", "private", "protected"}


class Token:
    __slots__ = ("text", "line", "kind")

    def __init__(self, text, line, kind):
        self.text, self.line, self.kind = text, line, kind

    def __repr__(self):
        return f"{self.text}@{self.line}"


def tokenize(code):
    raw = []
    line = 1
    pos = 0
    for m in _TOKEN.finditer(code):
        line += code.count("\n", pos, m.start())
        pos = m.start()
        raw.append(Token(m.group(), line, m.lastgroup))
    # `operator` and the symbol it names become one identifier: `operator()`, `operator==`,
    # `operator new[]`, `operator bool`
    tokens = []
    i = 0
    while i < len(raw):
        t = raw[i]
        if t.text == "operator" and i + 1 < len(raw):
            nxt = raw[i + 1].text
            if nxt in ("(", "[") and i + 2 < len(raw) and raw[i + 2].text == {"(": ")", "[": "]"}[nxt]:
                tokens.append(Token("operator" + nxt + raw[i + 2].text, t.line, "id"))
                i += 3
                continue
            if nxt in ("new", "delete"):
                text, i = "operator " + nxt, i + 2
                if i + 1 < len(raw) and raw[i].text == "[" and raw[i + 1].text == "]":
                    text, i = text + "[]", i + 2
                tokens.append(Token(text, t.line, "id"))
                continue
            if raw[i + 1].kind == "op" and nxt not in ("{", ";"):
                tokens.append(Token("operator" + nxt, t.line, "id"))
                i += 2
                continue
            if raw[i + 1].kind == "str":  # a literal operator: operator""_x
                tokens.append(Token('operator""' + (raw[i + 2].text if i + 2 < len(raw) else ""), t.line, "id"))
                i += 3
                continue
            if raw[i + 1].kind == "id":  # a conversion: operator bool
                tokens.append(Token("operator " + nxt, t.line, "id"))
                i += 2
                continue
        tokens.append(t)
        i += 1
    return tokens


def _match_forward(tokens, i, open_, close):
    """Index of the token closing tokens[i] (== open_)."""
    depth = 0
    for j in range(i, len(tokens)):
        if tokens[j].text == open_:
            depth += 1
        elif tokens[j].text == close:
            depth -= 1
            if depth == 0:
                return j
    return -1


def _skip_template_header(stmt, i):
    """stmt[i] is `template`: the index after its `<...>`."""
    if i + 1 >= len(stmt) or stmt[i + 1].text != "<":
        return i + 1
    depth = 0
    for j in range(i + 1, len(stmt)):
        t = stmt[j].text
        if t == "(":
            j2 = _match_forward(stmt, j, "(", ")")
            if j2 < 0:
                return len(stmt)
            continue
        if t == "<":
            depth += 1
        elif t == ">":
            depth -= 1
        elif t == ">>":
            depth -= 2
        if depth <= 0:
            return j + 1
    return len(stmt)


def _strip_prefix(stmt):
    """Leading access specifiers, `template <...>` headers and attributes off a statement."""
    i = 0
    while i < len(stmt):
        t = stmt[i].text
        if t in _ACCESS and i + 1 < len(stmt) and stmt[i + 1].text == ":":
            i += 2
        elif t == "template":
            i = _skip_template_header(stmt, i)
        elif t == "[" and i + 1 < len(stmt) and stmt[i + 1].text == "[":
            j = _match_forward(stmt, i, "[", "]")
            i = len(stmt) if j < 0 else j + 1
        else:
            break
    return i


def _top_level_groups(stmt, start):
    """(open index, close index) of every ( ) group outside <...> and [...] from start on."""
    groups = []
    angle = 0
    i = start
    while i < len(stmt):
        t = stmt[i].text
        if t == "(":
            j = _match_forward(stmt, i, "(", ")")
            if j < 0:
                return groups
            if angle == 0:
                groups.append((i, j))
            i = j + 1
            continue
        if t == "[":
            j = _match_forward(stmt, i, "[", "]")
            if j < 0:
                return groups
            # a lambda introducer `[...]` is followed by its parameters: keep those visible
            i = j + 1
            continue
        if t == "<" and i > 0 and stmt[i - 1].kind == "id":
            angle += 1
        elif t == ">" and angle > 0:
            angle -= 1
        elif t == ">>" and angle > 0:
            angle = max(0, angle - 2)
        i += 1
    return groups


def _name_before(stmt, k, start):
    """The (qualified) name ending just before stmt[k], e.g. `a::B<T>::c`, `operator()`, `~X`."""
    j = k - 1
    if j < start or stmt[j].kind != "id":
        return None
    parts = [stmt[j].text]
    j -= 1
    while j >= start:
        if stmt[j].text == "~":
            parts[-1] = "~" + parts[-1]
            j -= 1
        elif stmt[j].text == "::" and j - 1 >= start:
            j -= 1
            if stmt[j].text == ">":  # a template-id qualifier: skip back over its <...>
                depth = 0
                while j >= start:
                    if stmt[j].text == ">":
                        depth += 1
                    elif stmt[j].text == "<":
                        depth -= 1
                        if depth == 0:
                            break
                    j -= 1
                j -= 1
            if j >= start and stmt[j].kind == "id":
                parts.append(stmt[j].text)
                j -= 1
            else:
                break
        else:
            break
    return "::".join(reversed(parts))


def classify(stmt):
    """What the `{` that ends the statement `stmt` (tokens since the last `;`, `{` or `}` at this
    scope) opens: ('namespace', name), ('class', name), ('function', name), ('init', None) for a
    brace inside a constructor's initialiser list, or ('other', None)."""
    i = _strip_prefix(stmt)
    body = stmt[i:]
    if not body:
        return ("other", None)  # a bare block or a braced list
    words = [t.text for t in body]
    if words[0] == "namespace" or (words[0] == "inline" and words[1:2] == ["namespace"]):
        names = [t.text for t in body if t.kind == "id" and t.text not in ("namespace", "inline")]
        return ("namespace", "::".join(names))
    if words[0] == "extern" and len(body) >= 2 and body[1].kind == "str":
        if len(body) == 2:
            return ("namespace", "")
        body = body[2:]
        words = words[2:]
    if words[0] in ("class", "struct", "union"):
        groups = _top_level_groups(body, 0)
        if not groups or not _is_function_tail(body, groups[-1][1] + 1)[0]:
            ids = [t.text for t in body[1:] if t.kind == "id" and t.text not in ("final", "alignas")]
            # the name is the last identifier before `:` (bases) or the end
            head = []
            for t in body[1:]:
                if t.text == ":" or t.text == "<":
                    break
                head.append(t)
            names = [t.text for t in head if t.kind == "id" and t.text not in ("final", "alignas")]
            return ("class", names[-1] if names else (ids[0] if ids else "<anonymous>"))
    if words[0] == "enum":
        return ("other", None)
    for open_, close in _top_level_groups(body, 0):
        if open_ == 0:
            continue
        prev = body[open_ - 1]
        if prev.text in _NOT_A_DECLARATOR:
            continue
        if prev.text == "]":  # a lambda's parameters
            name = _lambda_name(body)
        elif prev.kind == "id":
            name = _name_before(body, open_, 0)
        else:
            continue
        ok, init = _is_function_tail(body, close + 1)
        if not ok:
            continue
        if init and body[-1].kind == "id" or init and body[-1].text == ">":
            return ("init", None)
        return ("function", name)
    # a lambda without parameters at namespace or class scope: `auto f = [] {`
    if body[-1].text == "]":
        j = len(body) - 1
        depth = 0
        while j >= 0:
            if body[j].text == "]":
                depth += 1
            elif body[j].text == "[":
                depth -= 1
                if depth == 0:
                    break
            j -= 1
        if j > 0 and body[j - 1].text in ("=", "(", ","):
            return ("function", _lambda_name(body))
    return ("other", None)


def _lambda_name(body):
    for j, t in enumerate(body):
        if t.text == "=" and j > 0 and body[j - 1].kind == "id":
            return body[j - 1].text
    return "<lambda>"


def _is_function_tail(body, k):
    """Whether the tokens body[k:] may follow a function's parameter list up to its body:
    qualifiers, a trailing return type, a requires clause, a constructor's initialiser list.
    Returns (ok, whether an initialiser list started)."""
    while k < len(body):
        t = body[k].text
        if t in _TRAILERS:
            k += 1
            if k < len(body) and body[k].text == "(" and t in ("noexcept", "throw"):
                j = _match_forward(body, k, "(", ")")
                if j < 0:
                    return (False, False)
                k = j + 1
            continue
        if t in ("->", "requires"):
            return (True, False)  # the rest is a type or a constraint
        if t == ":":
            return (True, True)
        return (False, False)
    return (True, False)


# ---------------------------------------------------------------------------------------------
# The scan: a stack of scopes over the tokens.

class Item:
    __slots__ = ("kind", "name", "path", "start", "end")

    def __init__(self, kind, name, path, start, end):
        self.kind, self.name, self.path, self.start, self.end = kind, name, path, start, end

    @property
    def lines(self):
        return self.end - self.start + 1

    def __repr__(self):
        return f"{self.kind} {self.name} {self.start}-{self.end}"


def scan(text, path="<text>"):
    """Every function and class definition in `text` (list of Item)."""
    tokens = tokenize(blank_non_code(text))
    items = []
    # scope: (kind, qualified name prefix) with kind in namespace/class/other
    scopes = [("namespace", [])]
    stmt = []
    i = 0
    while i < len(tokens):
        t = tokens[i]
        if t.text in (";",):
            stmt = []
            i += 1
            continue
        if t.text == "}":
            if len(scopes) == 1:
                raise ParseError(f"{path}:{t.line}: unmatched '}}'")
            scopes.pop()
            stmt = []
            i += 1
            continue
        if t.text == "(" or t.text == "[":  # braces inside parentheses: default arguments, calls
            j = _match_forward(tokens, i, t.text, ")" if t.text == "(" else "]")
            if j < 0:
                raise ParseError(f"{path}:{t.line}: unmatched '{t.text}'")
            stmt.extend(tokens[i:j + 1])
            i = j + 1
            continue
        if t.text != "{":
            stmt.append(t)
            i += 1
            continue
        end = _match_forward(tokens, i, "{", "}")
        if end < 0:
            raise ParseError(f"{path}:{t.line}: unmatched '{{'")
        kind, name = classify(stmt)
        start_line = stmt[_strip_access(stmt)].line if stmt and _strip_access(stmt) < len(stmt) else t.line
        prefix = scopes[-1][1]
        if kind in ("function", "init"):
            if kind == "init":  # a member's braced initialiser: part of the statement
                stmt = stmt + [Token("{", t.line, "op"), Token("}", tokens[end].line, "op")]
                i = end + 1
                continue
            items.append(Item("function", "::".join(prefix + [name]), path, start_line, tokens[end].line))
            stmt = []
            i = end + 1  # the body, lambdas and local classes included, is the function's
            continue
        if kind == "class":
            items.append(Item("class", "::".join(prefix + [name]), path, start_line, tokens[end].line))
            scopes.append(("class", prefix + [name]))
        elif kind == "namespace":
            scopes.append(("namespace", prefix + ([name] if name else [])))
        else:  # an initialiser or enum: nothing in it is counted
            stmt.extend(tokens[i:end + 1])
            i = end + 1
            continue
        stmt = []
        i += 1
    if len(scopes) != 1:
        raise ParseError(f"{path}: unbalanced braces at the end of the file")
    return items


def _strip_access(stmt):
    i = 0
    while i + 1 < len(stmt) and stmt[i].text in _ACCESS and stmt[i + 1].text == ":":
        i += 2
    return i


# ---------------------------------------------------------------------------------------------

def offenders(root):
    """(key, message) of every definition or file over its limit under root/libbtf."""
    found = []
    files = sorted(p for p in (root / "libbtf").rglob("*") if p.suffix in (".h", ".cpp") and p.is_file())
    for f in files:
        rel = f.relative_to(root).as_posix()
        text = f.read_text(encoding="utf-8")
        n_lines = len(text.splitlines())
        if f.suffix == ".cpp" and n_lines > FILE_LIMIT:
            found.append((rel, f"{rel}:1: file has {n_lines} lines (limit {FILE_LIMIT})"))
        for item in scan(text, rel):
            limit = FUNCTION_LIMIT if item.kind == "function" else CLASS_LIMIT
            if item.lines > limit:
                found.append((f"{rel}:{item.name}",
                              f"{rel}:{item.start}: {item.kind} {item.name} has {item.lines} lines (limit {limit})"))
    return found, len(files)


def read_allow(path):
    allow = []
    if path is None:
        return allow
    for line in pathlib.Path(path).read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            allow.append(line)
    return allow


def check(root, allow_path, out=sys.stdout, err=sys.stderr):
    found, n_files = offenders(root)
    allow = read_allow(allow_path)
    errors = [msg for key, msg in found if key not in allow]
    allowed = [msg for key, msg in found if key in allow]
    keys = {key for key, _ in found}
    stale = [a for a in allow if a not in keys]
    for msg in allowed:
        print(f"allowed (size limits allow-list): {msg}", file=out)
    for a in stale:
        errors.append(f"allow-list entry '{a}' matches no offender: remove it from {allow_path}")
    if errors:
        print("code size limits exceeded:", file=err)
        for e in errors:
            print("  " + e, file=err)
        return 1
    print(f"sizes: {n_files} files, every function <= {FUNCTION_LIMIT} lines, class <= {CLASS_LIMIT}, "
          f".cpp <= {FILE_LIMIT} ({len(allowed)} allow-listed)", file=out)
    return 0


# ---------------------------------------------------------------------------------------------
# Self-test: snippets with known definitions and lengths.

_SELF_TESTS = [
    # (source, [(kind, name, start line, lines)])
    ("int f() { return 1; }\n", [("function", "f", 1, 1)]),
    ("void f()\n{\n}\n", [("function", "f", 1, 3)]),
    # comments, strings, chars and raw strings with braces; a lambda inside
    ("namespace a {\n"
     "// {{ a comment brace\n"
     "/* { */ int g(int x) {\n"
     "  const char* s = \"}{\\\"}\";\n"
     "  char c = '{', d = '\\'';\n"
     "  auto l = [&](int y) { return y + '}'; };\n"
     "  const char* r = R\"xy(}} )\" {)xy\";\n"
     "  int n = 1'000'000;\n"
     "  return l(x) + n;\n"
     "}\n"
     "}  // namespace a\n",
     [("function", "a::g", 3, 8)]),
    # a class with an in-class member, a constructor with an initialiser list (braces too),
    # a template member, an enum and a braced member initialiser
    ("template <typename T>\n"
     "class Box : public Base<T> {\n"
     " public:\n"
     "  explicit Box(int a)\n"
     "      : Base<T>{a},\n"
     "        v_(a), w_{a, 2} {\n"
     "    if (a) { v_ = 1; }\n"
     "  }\n"
     "  template <class U> U get() const noexcept { return U{v_}; }\n"
     "  enum class E { kA, kB };\n"
     "  int w_[2]{0, 0};\n"
     "  int v_ = 0;\n"
     "  struct Inner { int f() { return 2; } };\n"
     "};\n",
     [("class", "Box", 1, 14), ("function", "Box::Box", 4, 5), ("function", "Box::get", 9, 1),
      ("class", "Box::Inner", 13, 1), ("function", "Box::Inner::f", 13, 1)]),
    # out-of-class definitions, operators, trailing return types, defaulted and declared ones
    ("struct S { S(); bool operator==(const S&) const = default; int g(); };\n"
     "S::S() = default;\n"
     "auto S::g() -> int\n"
     "{\n"
     "  return 3;\n"
     "}\n"
     "bool operator<(const S&, const S&) { return false; }\n"
     "S::~S() {\n"
     "}\n"
     "int S::operator()(int x) const { return x; }\n"
     "static const int kTable[] = {1, 2, 3};\n"
     "const auto kLambda = [](int x) {\n"
     "  return x;\n"
     "};\n"
     "extern \"C\" {\n"
     "int c_func(void) { return 0; }\n"
     "}\n"
     "#define MACRO(x) { x }\n"
     "#if 0\n"
     "#endif\n",
     [("class", "S", 1, 1), ("function", "S::g", 3, 4), ("function", "operator<", 7, 1),
      ("function", "S::~S", 8, 2), ("function", "S::operator()", 10, 1),
      ("function", "kLambda", 12, 3), ("function", "c_func", 16, 1)]),
    # default arguments with braces and a function returning a template type
    ("std::function<void(int)> make(std::vector<int> v = {}, int k = int{3}) {\n"
     "  return [v](int) {};\n"
     "}\n",
     [("function", "make", 1, 3)]),
]


def self_test():
    failures = []
    for src, want in _SELF_TESTS:
        got = [(it.kind, it.name, it.start, it.lines) for it in scan(src)]
        if sorted(got) != sorted(want):
            failures.append(f"snippet:\n{src}\nwant {sorted(want)}\n got {sorted(got)}")
    for bad in ("void f() {\n", "void f() { } }\n", "const char* s = \"abc;\n"):
        try:
            scan(bad)
            failures.append(f"no parse error for {bad!r}")
        except ParseError:
            pass
    # the check itself: an oversized function, class and file fail; the allow-list exempts them
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        (root / "libbtf" / "m").mkdir(parents=True)
        long_fn = "void big() {\n" + "  x();\n" * (FUNCTION_LIMIT - 2) + "}\n"  # exactly the limit
        (root / "libbtf" / "m" / "ok.cpp").write_text(long_fn)
        longer = "void bigger() {\n" + "  x();\n" * (FUNCTION_LIMIT - 1) + "}\n"  # one over
        cls = "struct C {\n" + "  int a;\n" * (CLASS_LIMIT - 1) + "};\n"  # one over
        (root / "libbtf" / "m" / "bad.h").write_text(longer + cls)
        (root / "libbtf" / "m" / "long.cpp").write_text("int x;\n" * (FILE_LIMIT + 1))
        found, _ = offenders(root)
        keys = sorted(k for k, _ in found)
        want = ["libbtf/m/bad.h:C", "libbtf/m/bad.h:bigger", "libbtf/m/long.cpp"]
        if keys != want:
            failures.append(f"offenders: want {want}, got {keys}")
        allow = root / "allow.txt"
        allow.write_text("# comment\n" + "\n".join(want) + "\n")
        if check(root, allow, io.StringIO(), io.StringIO()) != 0:
            failures.append("the allow-list did not exempt the offenders")
        allow.write_text("\n".join(want[:2]) + "\n")
        if check(root, allow, io.StringIO(), io.StringIO()) == 0:
            failures.append("an offender missing from the allow-list passed")
        allow.write_text("\n".join(want + ["libbtf/m/ok.cpp:big"]) + "\n")
        if check(root, allow, io.StringIO(), io.StringIO()) == 0:
            failures.append("a stale allow-list entry passed")
    if failures:
        print("check_sizes self-test FAILED:\n" + "\n\n".join(failures), file=sys.stderr)
        return 1
    print(f"check_sizes self-test: {len(_SELF_TESTS)} snippets and the allow-list behave")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source-dir", type=pathlib.Path)
    ap.add_argument("--allow", type=pathlib.Path)
    ap.add_argument("--self-test", action="store_true")
    ap.add_argument("--list", action="store_true", help="print every definition with its length")
    args = ap.parse_args()
    try:
        if args.self_test:
            return self_test()
        if args.source_dir is None:
            ap.error("--source-dir is required")
        if args.list:
            for f in sorted((args.source_dir / "libbtf").rglob("*")):
                if f.suffix in (".h", ".cpp"):
                    rel = f.relative_to(args.source_dir).as_posix()
                    for it in scan(f.read_text(encoding="utf-8"), rel):
                        print(f"{it.lines:5d} {it.kind:8s} {rel}:{it.start} {it.name}")
            return 0
        return check(args.source_dir, args.allow)
    except ParseError as e:
        print(f"check_sizes: cannot parse: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
