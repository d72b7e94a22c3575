#!/usr/bin/env python3
"""Lists the C++ function definitions longer than a limit, longest first.

Usage: function_lengths.py [--limit N] [--top N] [--fail] [--junit FILE] [PATH...]

PATH: files or folders (searched for *.cpp, *.hpp, *.h, *.cc); default: the production code,
i.e. src/, tools/, nodes/ and ros/ of gear_damping_id and gear_sim. A function's length counts
the lines from its declarator (return type and name) to its closing brace, comments and blank
lines included; a lambda or local class counts towards the function that holds it.
Without --top, prints every function over --limit (default 120); with --top N, the N longest
whatever their length. Exit status: 0, or with --fail 1 when any function is over the limit.
--junit FILE also writes one JUnit test case (failed when any function is over the limit), so
that CI counts the check with the other tests.

A brace-matching heuristic, not a parser: comments, string and character literals and
preprocessor lines are blanked first, then every '{' at namespace or class scope whose header
(the text since the previous ';', '{' or '}') has a parameter list and is not a namespace, a
class or an initialiser opens a function.
"""
import argparse
import pathlib
import re
import sys

DEFAULT_DIRS = [
    f"{component}/{part}"
    for component in ("gear_damping_id", "gear_sim")
    for part in ("src", "tools", "nodes", "ros")
]
SUFFIXES = {".cpp", ".hpp", ".h", ".cc"}
CONTROL = {"if", "for", "while", "switch", "catch", "do", "else", "try", "return"}
CLASS_KEYS = re.compile(r"\b(class|struct|union|enum)\b")


def blank_code(text: str) -> str:
    """Comments, literals and preprocessor lines replaced by spaces (newlines kept)."""
    out = []
    i, n = 0, len(text)
    line_start = True
    while i < n:
        c = text[i]
        if line_start and c == "#":
            # A preprocessor line, with its continuations.
            j = i
            while j < n and (text[j] != "\n" or text[j - 1] == "\\"):
                j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        if c == "\n":
            line_start = True
            out.append(c)
            i += 1
            continue
        if not c.isspace():
            line_start = False
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not text[i - 1].isalnum()):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            end = text.find(")" + m.group(1) + '"', i)
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c in "\"'":
            if c == "'" and i > 0 and text[i - 1].isalnum():  # digit separator 1'000
                out.append(" ")
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


OPERATOR = re.compile(
    r"((?:[\w~]+\s*::\s*)*operator\s*(?:\(\s*\)|\[\s*\]|[^\s\w(]+|[\w:<>*& ]+?))\s*\("
)


def strip_templates(head: str) -> str:
    """The header without its 'template <...>' prefixes (nested angle brackets included)."""
    while True:
        m = re.match(r"\s*template\s*<", head)
        if not m:
            return head
        depth, i = 1, m.end()
        while i < len(head) and depth:
            depth += {"<": 1, ">": -1}.get(head[i], 0)
            i += 1
        head = head[i:]


def function_name(header: str):
    """The qualified name of a function definition's header, or None when it is not one."""
    head = strip_templates(" ".join(header.split()))
    if not head or "(" not in head:
        return None
    first = head.split()[0].split("(")[0]
    if first in CONTROL or first in ("namespace", "extern"):
        return None
    m = OPERATOR.search(head)
    if m:
        before, name = head[: m.start()], m.group(1)
    else:
        before = head[: head.index("(")]
        m = re.search(r"((?:[\w~]+\s*::\s*)*~?\w+)\s*$", before)
        if not m:
            return None
        before, name = before[: m.start()], m.group(1)
    if CLASS_KEYS.search(before) or "=" in before:
        return None
    return re.sub(r"\s*::\s*", "::", " ".join(name.split()))


def has_init_list(header: str) -> bool:
    """Whether a function header ends in a constructor's member initialiser list: a ':' (not
    '::') after the parameter list's closing parenthesis."""
    depth, closed = 0, False
    for i, c in enumerate(header):
        if c == "(":
            depth += 1
        elif c == ")":
            depth -= 1
            closed = closed or depth == 0
        elif c == ":" and closed and depth == 0:
            if header[i + 1 : i + 2] != ":" and header[i - 1 : i] != ":":
                return True
    return False


def matching_brace(code: str, i: int) -> int:
    """The index of the '}' that closes the '{' at i (len(code) when there is none)."""
    depth = 0
    for j in range(i, len(code)):
        if code[j] == "{":
            depth += 1
        elif code[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(code)


def functions(path: pathlib.Path):
    """Yields (name, first line, last line) of every function defined in the file."""
    code = blank_code(path.read_text(encoding="utf-8", errors="replace"))
    stack = []  # scope kinds: 'ns', 'class', 'func', 'block'
    open_func = None
    header_start = 0
    i = 0
    while i < len(code):
        c = code[i]
        if c == "{":
            kind = "block"
            if not stack or stack[-1] in ("ns", "class"):
                header = code[header_start:i]
                words = header.split()
                name = function_name(header) if words else None
                if words and (words[0] == "namespace" or words[:2] == ["inline", "namespace"]
                              or words[0] == "extern"):
                    kind = "ns"
                elif name is not None and has_init_list(header) and re.search(
                    r"[\w>]\s*$", header
                ):
                    # A member's brace initialiser (x_{0}) inside the initialiser list: still
                    # the header.
                    i = matching_brace(code, i) + 1
                    continue
                elif name is not None:
                    kind = "func"
                    offset = len(header) - len(header.lstrip())
                    first = code.count("\n", 0, header_start + offset) + 1
                    open_func = (name, first, len(stack))
                elif words and CLASS_KEYS.search(strip_templates(header).split("(")[0]):
                    kind = "class"
            stack.append(kind)
            header_start = i + 1
        elif c == "}":
            if stack:
                kind = stack.pop()
                if kind == "func" and open_func is not None and open_func[2] == len(stack):
                    yield open_func[0], open_func[1], code.count("\n", 0, i) + 1
                    open_func = None
            header_start = i + 1
        elif c == ";" or (c == ":" and stack and stack[-1] == "class" and _access_label(code, i)):
            header_start = i + 1
        i += 1


def _access_label(code: str, i: int) -> bool:
    """Whether the ':' at i ends 'public:', 'protected:' or 'private:'."""
    return re.search(r"\b(public|protected|private)\s*$", code[max(0, i - 20) : i]) is not None


def sources(paths):
    for p in paths:
        p = pathlib.Path(p)
        if p.is_file():
            yield p
        elif p.is_dir():
            yield from sorted(f for f in p.rglob("*") if f.suffix in SUFFIXES and f.is_file())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*")
    ap.add_argument("--limit", type=int, default=120)
    ap.add_argument("--top", type=int, default=0)
    ap.add_argument("--fail", action="store_true")
    ap.add_argument("--junit", type=pathlib.Path)
    args = ap.parse_args()
    repo = pathlib.Path(__file__).resolve().parent.parent
    paths = args.paths or [repo / d for d in DEFAULT_DIRS]
    rows = []
    for f in sources(paths):
        try:
            shown = f.resolve().relative_to(repo)
        except ValueError:
            shown = f
        for name, first, last in functions(f):
            rows.append((last - first + 1, f"{shown}:{first}", name))
    rows.sort(key=lambda r: (-r[0], r[1]))
    over = [r for r in rows if r[0] > args.limit]
    shown_rows = rows[: args.top] if args.top else over
    for length, where, name in shown_rows:
        print(f"{length:5d}  {where}  {name}")
    print(
        f"function_lengths: {len(over)} function(s) over {args.limit} lines "
        f"(of {len(rows)} defined)",
        file=sys.stderr,
    )
    if args.junit:
        write_junit(args.junit, over, args.limit)
    return 1 if args.fail and over else 0


def write_junit(path: pathlib.Path, over: list, limit: int) -> None:
    """One test case, FunctionLengths.NoFunctionOverTheLimit, failed when `over` is not empty."""
    from xml.sax.saxutils import quoteattr, escape

    path.parent.mkdir(parents=True, exist_ok=True)
    case = '  <testcase classname="function_lengths" name="NoFunctionOverTheLimit">'
    if over:
        listing = "\n".join(f"{n} lines {w} {name}" for n, w, name in over)
        message = quoteattr(f"{len(over)} function(s) over {limit} lines")
        case += f"\n    <failure message={message}>{escape(listing)}</failure>\n  "
    case += "</testcase>"
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<testsuite name="function_lengths" tests="1" failures="{int(bool(over))}">\n'
        f"{case}\n</testsuite>\n"
    )


if __name__ == "__main__":
    sys.exit(main())
