#!/usr/bin/env bash
# The product as a lab's IT installs it: build a wheel, install it (not editable) into a fresh virtual
# environment, and run a short study, its check, a report, a participant's export and a withdrawal from the
# installed package, in a folder outside the checkout -- so a module or data file the wheel leaves out fails here.
#
# The fresh environment borrows the dependencies (Qt, SciPy, pandas, ...) of the checkout's .venv through a
# path file instead of installing them again (that takes minutes): only haptic-study's own files come from the
# wheel; the checkout's editable install is not visible in it (a path file's folder is searched, its own path
# files are not run), which the script checks.  Because the dependencies are borrowed, what the wheel *declares*
# is checked apart: its Requires-Dist, entry points and version are pyproject.toml's, and it holds exactly the
# product's modules and data files.  Needs ./scripts/setup.sh first.  ~30 s.
set -euo pipefail
cd "$(dirname "$0")/.."
SRC=$(pwd)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/haptic-wheel.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

echo "wheel: building"
# from a copy of the source (the checkout's files, tracked or new, less what git ignores): setuptools builds in
# ./build and puts everything left in build/lib into the wheel, so a wheel built in a checkout ships the modules
# an earlier build saw even once they are deleted or renamed -- and an import of one would pass here
mkdir "$WORK/src"
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    git ls-files -z -co --exclude-standard | while IFS= read -r -d '' f; do [ -e "$f" ] && printf '%s\0' "$f"; done \
        | tar -c --null -T - -f - | tar -x -C "$WORK/src"
else
    tar -c --exclude=./.venv --exclude=./build --exclude='*.egg-info' --exclude=__pycache__ -f - . | tar -x -C "$WORK/src"
fi
(cd "$WORK/src" && "$SRC/.venv/bin/python" -m pip wheel -q --no-deps -w "$WORK/dist" .) >"$WORK/build.log" 2>&1 \
    || { cat "$WORK/build.log"; exit 1; }
WHEEL=$(ls "$WORK"/dist/haptic_study-*.whl)
echo "wheel: $(basename "$WHEEL"): installing into a fresh environment"
PY=$(.venv/bin/python -c 'import sys; print(sys._base_executable)')
"$PY" -m venv --without-pip "$WORK/venv"  # pip from .venv installs into it (--python): no second pip to set up
.venv/bin/python -m pip --python "$WORK/venv/bin/python" install -q --no-deps --no-index "$WHEEL"
DEPS=$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
SITE=$("$WORK/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
echo "$DEPS" > "$SITE/haptic-study-dependencies.pth"

cd "$WORK"  # outside the checkout: nothing can be imported from the source tree
"$WORK/venv/bin/python" - "$SITE" "$SRC" <<'EOF'
import sys
site, src = sys.argv[1], sys.argv[2]
import analysis, bench, pipeline, protocol, study_app  # noqa: E401
from protocol.storage import schema_path
for m in (analysis, bench, pipeline, protocol, study_app):
    assert m.__file__.startswith(site), f"{m.__name__} imported from {m.__file__}, not from the installed wheel"
assert str(schema_path()).startswith(site) and schema_path().is_file(), schema_path()
venv = f"{src}/.venv/"
assert not any((p == src or p.startswith(src + "/")) and not p.startswith(venv) for p in sys.path), sys.path
from study_app.guide_paths import guide, hardware_template
for path in (guide("gui.md"), guide("hardware-setup.md"), hardware_template()):
    assert path.startswith(site) and open(path, encoding="utf-8").read(), f"{path}: not the installed copy"
print(f"wheel: every package imports from {site}, the guides are in it")
EOF
HS="$WORK/venv/bin/haptic-study"
"$HS" --version | tee version.txt
grep -q "not a git checkout" version.txt
# what the wheel declares: pip installs its dependencies from Requires-Dist (the pins: PySide6-Essentials<6.12,
# scipy, statsmodels), the command and the benchmarks come from its entry points; and it ships the product's modules
# and data files, no fewer and no more
"$WORK/venv/bin/python" - "$WORK/src" "$WHEEL" <<'EOF'
import sys, tomllib, zipfile
from importlib import metadata
from pathlib import Path
from packaging.requirements import Requirement
src, wheel = Path(sys.argv[1]), sys.argv[2]
project = tomllib.loads((src / "pyproject.toml").read_text(encoding="utf-8"))["project"]
dist = metadata.distribution("haptic-study")
assert dist.version == project["version"], (dist.version, project["version"])
def reqs(lines):
    return sorted(str(Requirement(r)) for r in lines)
declared = [r for r in dist.requires or [] if "extra ==" not in r]
assert reqs(declared) == reqs(project["dependencies"]), f"Requires-Dist {declared} != {project['dependencies']}"
qt = [Requirement(r) for r in declared if Requirement(r).name == "PySide6-Essentials"]
assert qt and not qt[0].specifier.contains("6.12.0"), f"PySide6-Essentials 6.12.0 is allowed: {qt} (docs/hardware.md §1)"
want = {("console_scripts", n, v) for n, v in project["scripts"].items()}
want |= {(g, n, v) for g, eps in project["entry-points"].items() for n, v in eps.items()}
got = {(ep.group, ep.name, ep.value) for ep in dist.entry_points}
assert got == want, f"entry points {sorted(got)} != pyproject.toml's {sorted(want)}"
shipped = {n for n in zipfile.ZipFile(wheel).namelist() if ".dist-info/" not in n}
floors = ("foundation", "pipeline", "protocol", "analysis", "study_app", "bench")
source = {p.relative_to(src).as_posix() for f in floors for p in (src / f).rglob("*.py") if "__pycache__" not in p.parts}
source |= {"protocol/study/default.toml", "protocol/storage/sql/schema.sql", "study_app/guide/template/hardware.example.toml"}
source |= {f"study_app/guide/{p.name}" for p in (src / "docs").glob("*.md")}  # the guides the help names
assert shipped == source, f"the wheel lacks {sorted(source - shipped)}, and ships {sorted(shipped - source)} besides"
print(f"wheel: {len(shipped)} files, Requires-Dist and entry points as pyproject.toml says "
      f"({', '.join(r for r in declared if r.startswith('PySide6'))})")
EOF
# every command's and subcommand's help, as the installed parser builds it (the benchmarks' from the entry point)
"$WORK/venv/bin/python" - <<'EOF'
import argparse, contextlib, io
from study_app.cli.main import build_parser
def subcommands(parser):
    return [(n, p) for a in parser._actions if isinstance(a, argparse._SubParsersAction) for n, p in a.choices.items()]
def walk(parser, path):
    with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):
        build_parser().parse_args([*path, "--help"])
    assert out.getvalue().startswith(" ".join(["usage: haptic-study", *path])), (path, out.getvalue()[:300])
    return 1 + sum(walk(sub, [*path, name]) for name, sub in subcommands(parser))
top = build_parser()
assert "bench" in dict(subcommands(top)), "no bench command: the entry point haptic_study.commands is not installed"
print(f"wheel: --help of {walk(top, [])} commands and subcommands")
EOF
"$WORK/venv/bin/python" - <<'EOF'
from importlib import resources
text = resources.files("protocol.study").joinpath("default.toml").read_text(encoding="utf-8")
text = text.replace("trials_per_cell = 5 ", "trials_per_cell = 1 ").replace("\nenabled = true", "\nenabled = false")
text = text.replace("max_trial_s = 12.0", "max_trial_s = 4.0").replace("pause_s = 2.0", "pause_s = 1.0")
open("small.toml", "w", encoding="utf-8").write(text)
EOF
"$HS" run --participants 3 --seed 1 --protocol small.toml --db study.db --jobs 2 > run.txt 2>&1 || { cat run.txt; exit 1; }
tail -1 run.txt
"$HS" check --db study.db | tail -1
"$HS" export participant --db study.db --participant P01 --out P01-data > export.txt
cut -c1-100 export.txt
"$HS" withdraw --db study.db --participant P03 --reason "CI rehearsal" --yes P03 > withdraw.txt  # not | head: pipefail
head -1 withdraw.txt
SECONDS=0
"$HS" report --db study.db --out report > report.txt 2>&1 || { cat report.txt; exit 1; }
echo "wheel: report in ${SECONDS} s"
grep -q "1 participant withdrew; excluded" report/report.html
echo "wheel: a study, its check, an export, a withdrawal and a report ran from the installed package"
