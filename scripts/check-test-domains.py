#!/usr/bin/env python3
"""CTest runs tests in parallel, and every test that starts a server or a participant owns a DDS
domain (and a port, where it opens one): two tests on one domain answer each other's clients
and fail at random. This finds the domain ids and ports the tests name and fails when two tests
share one.

A test is a gtest TEST in tests/**/*.cpp, a script that CMake's add_test runs (its positional
arguments are read where the script names them, e.g. `cli=$2 domain=$3`), or python.pytest (all
of python/tests, one CTest test). Ids are found where they are written as:
  - ServerProcess NAME(DIR, ID ...), connect...(ID), .domain_id = ID, createParticipant({ID, ...;
  - there, ID may be an integer constant of the file or of the TEST (constexpr kDomain = ID);
  - the literals assigned to a variable named like a domain (domain = secure ? 194 : 193);
  - an argument of a helper of the same file whose parameter is named like a domain;
  - --domain-id ID and domain_id: ID in scripts; os.environ.get("..._DOMAIN", "ID") (+ k) in
    python/tests.
A TEST that starts a server (ServerProcess) with no id found here fails the check too, so that
a domain written some other way is not missed silently.
Usage: scripts/check-test-domains.py [REPO_ROOT]   (run by CTest as tests.DomainsAndPortsOwned)
"""
import collections
import pathlib
import re
import sys

ARGS = [a for a in sys.argv[1:] if a != "-v"]
ROOT = pathlib.Path(ARGS[0] if ARGS else pathlib.Path(__file__).parent.parent)
owners = collections.defaultdict(set)  # ("domain" | "port", id) -> {test}
unread = []  # TESTs that start a server on a domain this script cannot read

# A domain's position in C++; ID is an integer literal or a constant of the file or the TEST.
ID = r"(\w+)"
CPP_PATTERNS = [
    re.compile(r"ServerProcess\s+\w+\(\s*[^,()]+(?:\([^()]*\))?[^,()]*,\s*" + ID + r"\s*[,)]"),
    re.compile(r"\.domain_id\s*=\s*" + ID + r"\b"),
    re.compile(r"\bconnect\w*\(\s*" + ID + r"\s*[,)]"),
    re.compile(r"createParticipant\(\{\s*" + ID + r"\s*,"),
]
# Integer constants (constexpr NAME = 1, OTHER = 2;) and a domain variable's literals
# (domain = secure ? 194 : 193).
CONST_RE = re.compile(r"\b(?:constexpr|const)\s+[\w:]+\s+([^;()]*);")
DOMAIN_LITERALS_RE = re.compile(r"\b\w*[Dd]omain\w*\s*=\s*([^;]*);")
TEST_RE = re.compile(r"^\s*TEST(?:_F|_P)?\(\s*(\w+)\s*,\s*(\w+)\s*\)", re.M)
FUNC_RE = re.compile(r"^[\w:<>,\s\*&]+?\b(\w+)\(([^)]*)\)\s*(?:->[^{]*)?\{", re.M)


def constants(text):
    found = {}
    for m in CONST_RE.finditer(text):
        for name, value in re.findall(r"(\w+)\s*=\s*(\d+)\b", m.group(1)):
            found[name] = int(value)
    return found


def split_args(text, start):
    """The top-level arguments of the call whose '(' is at text[start]."""
    depth, args, cur = 0, [], []
    for ch in text[start:]:
        if ch in "([{":
            depth += 1
            if depth == 1:
                continue
        elif ch in ")]}":
            depth -= 1
            if depth == 0:
                args.append("".join(cur).strip())
                return args
        if ch == "," and depth == 1:
            args.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
    return args


def cpp_file(path):
    text = path.read_text(errors="replace")
    tests = list(TEST_RE.finditer(text))
    if not tests:
        return
    rel = path.relative_to(ROOT)
    file_constants = constants(text[: tests[0].start()])
    helpers = {}  # function name -> index of its domain parameter
    for m in FUNC_RE.finditer(text):
        params = [p.strip() for p in m.group(2).split(",")]
        for i, p in enumerate(params):
            if re.search(r"[Dd]omain\w*\s*(=.*)?$", p) and "domains" not in p:
                helpers[m.group(1)] = i
    for n, m in enumerate(tests):
        body = text[m.start(): tests[n + 1].start() if n + 1 < len(tests) else len(text)]
        name = f"{rel}:{m.group(1)}.{m.group(2)}"
        known = {**file_constants, **constants(body)}

        def own(token):
            value = int(token) if token.isdigit() else known.get(token)
            if value is not None:
                owners[("domain", value)].add(name)

        for pattern in CPP_PATTERNS:
            for hit in pattern.finditer(body):
                own(hit.group(1))
        for hit in DOMAIN_LITERALS_RE.finditer(body):
            for literal in re.findall(r"\b\d+\b", hit.group(1)):
                own(literal)
        for helper, index in helpers.items():
            for call in re.finditer(rf"\b{helper}\(", body):
                args = split_args(body, call.end() - 1)
                if index < len(args) and re.fullmatch(r"\w+", args[index]):
                    own(args[index])
        if "ServerProcess" in body and not any(name in t for t in owners.values()):
            unread.append(name)


def script_roles(script):
    """{position: role} from a script's `a=$1 b=$2` line, for the roles domain and port."""
    roles = {}
    for line in script.read_text(errors="replace").splitlines():
        for role, pos in re.findall(r"\b(domain|port)=\$(\d+)\b", line):
            roles[int(pos)] = role
    return roles


def cmake_file(path):
    text = path.read_text(errors="replace")
    for m in re.finditer(r"add_test\(\s*NAME\s+(\S+)\s+COMMAND\s+([^)]*(?:\)[^)]*)*?)\)\s*\n", text):
        name, tokens = m.group(1), m.group(2).split()
        for i, token in enumerate(tokens):
            if not token.endswith((".sh", ".py")):
                continue
            script = pathlib.Path(
                token.replace("${CMAKE_CURRENT_SOURCE_DIR}", str(path.parent))
                .replace("${PROJECT_SOURCE_DIR}", str(ROOT))
                .replace("${CMAKE_SOURCE_DIR}", str(ROOT)))
            if not script.exists():
                continue
            for pos, role in script_roles(script).items():
                if i + pos < len(tokens) and tokens[i + pos].isdigit():
                    owners[(role, int(tokens[i + pos]))].add(f"ctest:{name}")
            body = script.read_text(errors="replace")
            for hit in re.finditer(r"(?:--domain-id\s+|domain_id:\s*)(\d+)\b", body):
                owners[("domain", int(hit.group(1)))].add(f"ctest:{name}")
            break


def python_tests():
    for path in sorted((ROOT / "python" / "tests").glob("*.py")):
        text = path.read_text(errors="replace")
        bases = {}
        for m in re.finditer(r"environ\.get\(\s*\"(\w+)\",\s*\"(\d+)\"\)(\)?\s*\+\s*(\d+))?", text):
            bases[m.group(1)] = int(m.group(2))
            owners[("domain", int(m.group(2)) + int(m.group(4) or 0))].add("ctest:python.pytest")
        for var, env in re.findall(r"^(\w+)\s*=.*?environ\.get\(\s*\"(\w+)\"", text, re.M):
            for extra in re.findall(rf"\b{var}\s*\+\s*(\d+)", text):
                owners[("domain", bases[env] + int(extra))].add("ctest:python.pytest")


for path in sorted((ROOT / "tests").rglob("*.cpp")):
    if "node_modules" not in path.parts:
        cpp_file(path)
for path in sorted((ROOT / "tests").rglob("CMakeLists.txt")):
    cmake_file(path)
python_tests()

shared = {key: tests for key, tests in owners.items() if len(tests) > 1}
for t in unread:
    print(f"check-test-domains: {t} starts a server, but its domain is not written where this "
          "script reads it")
for (kind, value), tests in sorted(shared.items()):
    print(f"check-test-domains: {kind} {value} is used by {len(tests)} tests that may run at once:")
    for t in sorted(tests):
        print(f"  {t}")
domains = sorted(v for k, v in owners if k == "domain")
if "-v" in sys.argv:
    for (kind, value), tests in sorted(owners.items()):
        print(f"{kind} {value}: {', '.join(sorted(tests))}")
print(f"check-test-domains: {len(domains)} domain ids ({domains[0]}..{domains[-1]}), "
      f"{sum(1 for k, _ in owners if k == 'port')} ports; "
      + ("each owned by one test" if not shared else f"{len(shared)} shared"))
sys.exit(1 if shared or unread else 0)
