"""The user documentation stays true to the code: README.md and docs/*.md.

Every relative link resolves; every ``make TARGET``, ``ros2 run PKG EXE`` and ``ros2 launch PKG
FILE`` written in a code span or block exists (Makefile target, console script whose module is in
the package's own directory, launch file) with the ``--options`` given to it; every ``name:=``
given to a launch file is one of its arguments, every ``-p name:=`` given to a node is in its
config YAML; files and modules named in code spans exist; the README stays short, the user pages
short and each in the site's navigation (mkdocs.yml, which `make docs` builds in strict mode).
"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / 'README.md'] + sorted((ROOT / 'docs').glob('*.md'))
README_MAX_LINES = 150
# written by a command from the code (`make params`; its own test checks they are current)
GENERATED = {ROOT / 'docs' / n for n in ('parameters.md', 'launch_arguments.md', 'commands.md')}
# the user pages (not the generated reference, not the research record under docs/research/)
USER_DOCS_MAX_LINES = 2500
PAGE_MAX_LINES = 400

LINK = re.compile(r'!?\[[^\]]*\]\(([^)\s]+)\)')
FENCE = re.compile(r'```[^\n]*\n(.*?)```', re.S)
SPAN = re.compile(r'`([^`\n]+)`')
MAKE = re.compile(r'(?:^|[\s;(&|])make ([a-z][\w-]*)(?: ARGS="([^"]*)")?')
RUN = re.compile(r'ros2 run (\S+) (\S+)([^\n|;&]*)')
OPTION = re.compile(r'(?:^|\s)(--[a-z][\w-]*)')
LAUNCH = re.compile(r'ros2 launch (\S+) (\S+\.launch\.py)((?:[ \t]+[\w.]+:=\S*)*)')
ROS_PARAM = re.compile(r'-p ([\w.]+):=')


def _code(text: str):
    """Code blocks (line continuations joined, shell comments dropped) and inline code spans."""
    blocks = FENCE.findall(text)
    rest = FENCE.sub('', text)
    # indented blocks (4 spaces) are code too
    blocks += re.findall(r'(?:^(?: {4}|\t).*\n?)+', rest, re.M)
    blocks = [re.sub(r'(^|\s)#.*', '', b.replace('\\\n', ' ')) for b in blocks]
    return blocks + SPAN.findall(rest)


def _console_scripts():
    """{(package, executable): module file path} from every setup.py."""
    out = {}
    for setup in (ROOT / 'src').glob('*/setup.py'):
        pkg = setup.parent.name
        for exe, module in re.findall(r"'([\w-]+)\s*=\s*([\w.]+):\w+'", setup.read_text()):
            out[(pkg, exe)] = setup.parent / (module.replace('.', '/') + '.py')
    return out


def _make_targets():
    """{target: (package, executable) it runs, or None}."""
    text = (ROOT / 'Makefile').read_text()
    out = {}
    for target, body in re.findall(r'^([\w-]+):[^\n]*\n((?:\t[^\n]*\n?)*)', text, re.M):
        m = re.search(r'ros2 run (\S+) (\S+)', body)
        out[target] = (m.group(1), m.group(2)) if m else None
    return out


def _unknown_options(module: Path, args: str):
    """The --options in ``args`` that the command's module does not define."""
    text = module.read_text()
    return [o for o in OPTION.findall(args)
            if o not in ('--ros-args', '--help') and f"'{o}'" not in text]


def _pages_ids():
    return [str(p.relative_to(ROOT)) for p in PAGES]


def test_readme_is_short():
    n = len((ROOT / 'README.md').read_text().splitlines())
    assert n <= README_MAX_LINES, f'README.md has {n} lines (at most {README_MAX_LINES})'


@pytest.mark.parametrize('page', PAGES, ids=_pages_ids())
def test_links_resolve(page):
    broken, pending = [], []
    for target in LINK.findall(page.read_text()):
        if re.match(r'[a-z]+:', target) or target.startswith('#'):
            continue  # URLs, anchors within the page
        path = (page.parent / target.split('#')[0]).resolve()
        if not path.exists():
            (pending if path in GENERATED else broken).append(target)
    assert not broken, f'{page.name}: links to missing files: {broken}'
    if pending:
        pytest.skip(f'{page.name}: generated page(s) not in this tree yet: {pending}')


# the generated reference quotes the commands' own help texts: written from the code, not by hand
WRITTEN = [p for p in PAGES if p not in GENERATED]


@pytest.mark.parametrize('page', WRITTEN, ids=[str(p.relative_to(ROOT)) for p in WRITTEN])
def test_commands_exist(page):
    scripts, targets = _console_scripts(), _make_targets()
    bad = []
    for code in _code(page.read_text()):
        for target, args in MAKE.findall(code):
            if target not in targets:
                bad.append(f'make {target}: no such Makefile target')
            elif args and targets[target] in scripts and scripts[targets[target]].is_file():
                bad += [f'make {target} ARGS: no option {o}'
                        for o in _unknown_options(scripts[targets[target]], args)]
        for pkg, exe, args in RUN.findall(code):
            if pkg.isupper() or exe.isupper():
                continue  # a placeholder: ros2 run PKG EXE
            module = scripts.get((pkg, exe))
            if module is None:
                bad.append(f'ros2 run {pkg} {exe}: no such console script')
            elif not module.is_file():
                bad.append(f'ros2 run {pkg} {exe}: {module.relative_to(ROOT)} is not in {pkg}')
            else:
                bad += [f'ros2 run {pkg} {exe}: no option {o}' for o in _unknown_options(module, args)]
        for pkg, launch, args in LAUNCH.findall(code):
            path = ROOT / 'src' / pkg / 'launch' / launch
            if not path.is_file():
                bad.append(f'ros2 launch {pkg} {launch}: no such launch file')
                continue
            declared = path.read_text()
            for name in re.findall(r'([\w.]+):=', args):
                if f"'{name}'" not in declared:
                    bad.append(f'ros2 launch {pkg} {launch}: no launch argument {name}')
    assert not bad, f'{page.name}:\n' + '\n'.join(bad)


@pytest.mark.parametrize('page', WRITTEN, ids=[str(p.relative_to(ROOT)) for p in WRITTEN])
def test_node_parameters_exist(page):
    """``ros2 run PKG NODE --ros-args -p name:=value``: name is in config/NODE.yaml."""
    bad = []
    for code in _code(page.read_text()):
        for line in code.splitlines():
            m = RUN.search(line)
            if not m or '--ros-args' not in line:
                continue
            config = ROOT / 'config' / f'{m.group(2)}.yaml'
            if not config.is_file():
                bad.append(f'{line.strip()}: no {config.relative_to(ROOT)}')
                continue
            keys = set(re.findall(r'^\s+([\w.]+):', config.read_text(), re.M))
            bad += [f'{line.strip()}: {name} is not in {config.name}'
                    for name in ROS_PARAM.findall(line) if name not in keys]
    assert not bad, f'{page.name}:\n' + '\n'.join(bad)


PACKAGES = sorted(p.parent.name for p in (ROOT / 'src').glob('*/package.xml'))
FILE_REF = re.compile(r'^(?:src/)?([a-z_]+)/([\w/]+\.(?:py|yaml|msg|srv))$')
MODULE_REF = re.compile(r'^([a-z_]+)\.([a-z_][\w.]*)$')


def _file_exists(first: str, rest: str) -> bool:
    if first in PACKAGES:
        return any(p.is_file() for p in ((ROOT / 'src' / first / first / rest),
                                         (ROOT / 'src' / first / rest)))
    return (ROOT / first / rest).is_file()


def _module_exists(pkg: str, dotted: str) -> bool:
    """``pkg.a.b.c``: some prefix a[.b[.c]] is a module or package of pkg (the rest attributes)."""
    parts = dotted.split('.')
    base = ROOT / 'src' / pkg / pkg
    return any((base.joinpath(*parts[:n]).with_suffix('.py')).is_file()
               or (base.joinpath(*parts[:n]) / '__init__.py').is_file()
               for n in range(1, len(parts) + 1))


@pytest.mark.parametrize('page', PAGES, ids=_pages_ids())
def test_code_references_exist(page):
    """Files (``physics_sim/mjcf_world.py``, ``config/driver.yaml``) and modules
    (``skeleton_eval.metrics.eq18_error``) named in code spans exist."""
    bad = []
    for span in SPAN.findall(FENCE.sub('', page.read_text())):
        m = FILE_REF.match(span)
        if m and not _file_exists(*m.groups()):
            bad.append(span)
        m = MODULE_REF.match(span)
        if (m and not span.endswith(('.py', '.yaml', '.md', '.mcap')) and m.group(1) in PACKAGES
                and not _module_exists(*m.groups())):
            bad.append(span)
    assert not bad, f'{page.name}: no such file or module: {bad}'


def test_user_pages_are_short():
    pages = [p for p in sorted((ROOT / 'docs').glob('*.md')) if p not in GENERATED]
    lines = {p.name: len(p.read_text().splitlines()) for p in pages}
    long = {n: c for n, c in lines.items() if c > PAGE_MAX_LINES}
    assert not long, f'user pages over {PAGE_MAX_LINES} lines (move the record to docs/research/): {long}'
    assert sum(lines.values()) <= USER_DOCS_MAX_LINES, (sum(lines.values()), lines)


def _nav_pages(entries):
    for e in entries:
        for v in (e.values() if isinstance(e, dict) else [e]):
            if isinstance(v, list):
                yield from _nav_pages(v)
            else:
                yield v


def test_every_page_is_in_the_navigation():
    """mkdocs.yml's nav lists every page under docs/ and nothing else (`make docs` fails on
    either too; this says which without building the site)."""
    import yaml
    nav = set(_nav_pages(yaml.safe_load((ROOT / 'mkdocs.yml').read_text())['nav']))
    pages = {str(p.relative_to(ROOT / 'docs')) for p in (ROOT / 'docs').rglob('*.md')}
    assert not pages - nav, f'pages missing from the nav in mkdocs.yml: {sorted(pages - nav)}'
    assert not nav - pages, f'nav entries in mkdocs.yml without a page: {sorted(nav - pages)}'


def test_no_work_item_names():
    """Docs, code, comments and tests say what a thing is, not which work item made it: no
    issue numbers, hash-numbers or experiment branch names (docs/research/ included)."""
    import subprocess
    # (a line ending in "issue": its number wrapped onto the next line)
    pattern = r'issue [0-9]|\bissue$|#[0-9]{2}\b|\bcontrol[0-9]\b|\b(ab29|control30|fusion31)\b'
    res = subprocess.run(['git', 'grep', '-n', '-I', '-i', '-E', pattern, '--',
                          'docs', 'src', 'tests', 'README.md', 'config', 'launch', 'scripts',
                          ':!tests/test_docs.py',
                          # its text is part of the shared venv's stamp: cleaned when that changes
                          ':!scripts/setup.sh'],
                         cwd=ROOT, capture_output=True, text=True)
    if res.returncode not in (0, 1):
        pytest.skip(f'not a git checkout: {res.stderr.strip()}')
    assert res.stdout == '', res.stdout[:3000]
