#!/bin/bash
# Every importable real file through import, calibrate, compare, correct and diagnose, with
# wall times and exit codes, then the docs/real-data.md table (OUT_DIR/table.md):
# benchmarks/real_data.sh [OUT_DIR] (default /tmp/adcpdyn-real).
# Exit code 2 is a one-line refusal (e.g. nothing to compare against); a traceback is reported.
cd "$(dirname "$0")/.."
R=${ADCPDYN_REAL_DATA:-../shared/data/real}
OUT=${1:-/tmp/adcpdyn-real}
A=.venv/bin/adcpdyn
mkdir -p "$OUT"; : > "$OUT/summary.txt"
for f in RiverPro_test01.PD0 winriver01.PD0 winriver02_transect.PD0 RDI_withBT.000 vmdas02_os.ENR; do
  n=${f%.*}; d="$OUT/$n"; rm -rf "$d"; mkdir -p "$d"
  for step in import calibrate compare correct diagnose; do
    case $step in
      import) cmd=("$A" import "$R/$f" --out "$d/case.h5");;
      calibrate) cmd=("$A" calibrate "$d/case.h5" --out "$d/calib.json");;
      compare) cmd=("$A" compare "$d/case.h5" --calibration "$d/calib.json" --out "$d/cmp");;
      correct) cmd=("$A" correct "$d/case.h5" --calibration "$d/calib.json" --out "$d/corrected.h5");;
      diagnose) cmd=("$A" diagnose "$d/case.h5" --out "$d/diag.json");;
    esac
    start=$(date +%s.%N)
    "${cmd[@]}" > "$d/$step.log" 2>&1; rc=$?
    secs=$(python3 -c "print(f'{$(date +%s.%N) - $start:.1f}')")
    echo "$n $step exit $rc, $secs s" | tee -a "$OUT/summary.txt"
    if grep -q "Traceback" "$d/$step.log"; then echo "$n $step TRACEBACK" | tee -a "$OUT/summary.txt"; fi
  done
done
# the docs/real-data.md table, from what was written above
.venv/bin/python -m adcpdyn.benchmarks.real_table "$OUT" | tee "$OUT/table.md"
