#!/usr/bin/env bash
# Session call 1: GPU suite tests, ncu device time of the pyramid candidate, racecheck on 5 binaries in parallel.
cd "$(dirname "$0")/.."
bash tools/gpu_suite.sh tests > /dev/null 2>&1
mv "$OUT/summary.txt" "$OUT/summary_tests.txt"
B=.gpu/bin
IMG=.gpu/img/herzjesu0_5616x3744.png
{
for cfg in "--threshold 10 --max-keypoints 20000 --pyramid 8:1.2 --level-budget geometric --keypoint-size 40" \
           "--threshold 20 --max-keypoints 20000 --pyramid 8:1.2 --level-budget geometric --keypoint-size 40" \
           "--threshold 20 --max-keypoints 5000 --pyramid 8:1.2 --level-budget geometric --keypoint-size 40" \
           "--threshold 2 --max-keypoints 20000" ; do
  echo "== ncu extract $cfg"
  timeout 120 ncu --clock-control none --cache-control none --metrics gpu__time_duration.sum --csv \
     $B/clatch extract --backend cuda $IMG $cfg -o /tmp/n > /tmp/ncu.csv 2>&1; echo "rc $?"
  grep -E "wrote .*keypoints" /tmp/ncu.csv | head -2
  python3 - <<'PY'
import csv, collections
rows=[r for r in csv.reader(open('/tmp/ncu.csv')) if len(r)>10]
h=rows[0]; ki=h.index('Kernel Name'); vi=h.index('Metric Value'); ui=h.index('Metric Unit')
tot=0; per=collections.Counter(); n=collections.Counter()
for r in rows[1:]:
    v=float(r[vi].replace(',','')); u=r[ui]
    v = v/1e3 if u=='nsecond' else v if u=='usecond' else v*1e3
    tot+=v; k=r[ki].split('(')[0]; per[k]+=v; n[k]+=1
print(f"kernels {sum(n.values())}  device time {tot/1e3:.3f} ms")
for k,v in per.most_common(): print(f"  {k:40s} x{n[k]:3d} {v/1e3:.3f} ms")
PY
done
} > "$OUT/ncu.txt" 2>&1
for t in cuda_faults cuda_match cuda_pyramid cuda_detect cuda_describe; do
  ( s=$(date +%s); timeout 400 compute-sanitizer --tool racecheck $B/$t > /tmp/rc_$t.txt 2>&1; echo "rc=$? $(( $(date +%s) - s ))s" >> /tmp/rc_$t.txt ) &
done
wait
for t in cuda_faults cuda_match cuda_pyramid cuda_detect cuda_describe; do
  echo "== racecheck $t (whole, 5 binaries in parallel)"; grep -E "^test |^test result|SUMMARY|^rc=|panicked" /tmp/rc_$t.txt | tail -30
done > "$OUT/racecheck.txt"
cat "$OUT/summary_tests.txt"; grep -E "device time|^==" "$OUT/ncu.txt"; grep -E "^==|test result|SUMMARY|^rc=" "$OUT/racecheck.txt"
