#!/usr/bin/env bash
# The product as a lab's IT installs it: build a wheel, install it (not editable) into a fresh virtual
# environment, and run a short study, its check, a report, a participant's export and a withdrawal from the
# installed package, in a folder outside the checkout -- so a module or data file the wheel leaves out fails here.
#
# The fresh environment borrows the dependencies (Qt, SciPy, pandas, ...) of the checkout's .venv through a
# path file instead of installing them again (that takes minutes): only haptic-study's own files come from the
# wheel; the checkout's editable install is not visible in it (a path file's folder is searched, its own path
# files are not run), which the script checks.  Needs ./scripts/setup.sh first.  ~30 s.
set -euo pipefail
cd "$(dirname "$0")/.."
SRC=$(pwd)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/haptic-wheel.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

echo "wheel: building"
.venv/bin/python -m pip wheel -q --no-deps -w "$WORK/dist" . >"$WORK/build.log" 2>&1 || { cat "$WORK/build.log"; exit 1; }
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
print(f"wheel: every package imports from {site}")
EOF
HS="$WORK/venv/bin/haptic-study"
"$HS" --version | tee version.txt
grep -q "not a git checkout" version.txt
"$WORK/venv/bin/python" - <<'EOF'
from importlib import resources
text = resources.files("protocol").joinpath("default.toml").read_text(encoding="utf-8")
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
