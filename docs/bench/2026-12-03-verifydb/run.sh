#!/bin/bash
# One run: clatch's verification (default rules and COLMAP's rules) and COLMAP 3.8's matches_importer
# on the same putative matches, interleaved per round, 2 cores.
set -u
C=$(realpath ${C:-target/release/clatch})
OUT=${OUT:-bench-out}; DATA=${DATA:?DATA: the folder of strecha_herzjesu_p8 and sceaux_castle}
mkdir -p $OUT; cd $OUT
declare -A IMG=( [herz]=$DATA/strecha_herzjesu_p8/images [sceaux]=$DATA/sceaux_castle )
declare -A K=( [herz]=$DATA/strecha_herzjesu_p8/K.txt [sceaux]=$DATA/sceaux_castle/K.txt )
ROUNDS=${ROUNDS:-5}
for s in herz sceaux; do
  rm -rf imp_$s.db imp_$s-colmap
  $C colmap --images ${IMG[$s]} --camera-k ${K[$s]} --database imp_$s.db --backend cpu --no-verify --no-colmap > imp_$s.out
done
echo "load at start: $(cat /proc/loadavg)"
for r in $(seq 1 $ROUNDS); do
  for s in herz sceaux; do
    rm -rf v_$s.db v_$s-colmap n_$s.db n_$s-colmap t_$s.db
    $C colmap --images ${IMG[$s]} --camera-k ${K[$s]} --database v_$s.db --backend cpu --no-colmap > v_${s}_$r.out
    $C colmap --images ${IMG[$s]} --camera-k ${K[$s]} --database n_$s.db --backend cpu --no-colmap --no-neighbour-consistency > n_${s}_$r.out
    cp imp_$s.db t_$s.db
    /usr/bin/time -f "%e %U %S" -o t_${s}_$r.time colmap matches_importer --database_path t_$s.db \
      --match_list_path imp_$s-colmap/matches.txt --match_type raw --SiftMatching.use_gpu 0 > t_${s}_$r.log 2>&1
    v=$(grep "^  verify" v_${s}_$r.out | awk '{print $2}')
    n=$(grep "^  verify" n_${s}_$r.out | awk '{print $2}')
    t=$(awk '{print $1}' t_${s}_$r.time)
    echo "round $r $s clatch_default $v clatch_colmap_rules $n colmap_importer $t load $(cut -d' ' -f1 /proc/loadavg)"
  done
done
