#!/bin/sh
# the demo phantom (graphs/demo.ini, tled_cuda, 6 mm nodes, one 6 mm push), seeds 1-8:
# band error (mean displacement error within 15 mm outside the tumour, against the true field)
# with the register stage's label term (as shipped) and without (label_weight = 0)
cd "$(dirname "$0")"
tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs ARMSTG_PLUGIN_PATH=$PWD/build/plugins
band() { awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next} $c["metric"]=="err_mean" && $c["structure"]=="band" {print $c["value"]}' "$1"; }
cat .commit
printf "seed\tlabel_weight\tband_error_mm\ttumour_dice\n"
for s in 1 2 3 4 5 6 7 8; do for w in 1 0; do
  d=/tmp/t-$s-$w; rm -rf $d
  PHANTOM_SEED=$s TLED=tled_cuda NODE_SPACING=6.0 build/armstg run graphs/demo.ini --set tune.values=6 --set register.label_weight=$w --out $d --jobs 1 -q > /tmp/t-$s-$w.log 2>&1 || { echo "seed $s w $w failed"; tail -3 /tmp/t-$s-$w.log; }
  printf "%s\t%s\t%s\t%s\n" $s $w "$(band $d/metrics.tsv)" "$(awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next} $c["metric"]=="dice" && $c["structure"]~/tumou?r/ {print $c["value"]; exit}' $d/metrics.tsv)"
done; done
head -3 /tmp/t-1-1/metrics.tsv; grep -i "band\|dice" /tmp/t-1-1/metrics.tsv | head -8
