#!/bin/sh
# Fine nodes (the TLED issue, point 5): does the growth complete without an
# inverted integration point at a given node spacing?  One growth per case,
# spacing and model variant, the shipped graphs' levelset layers and push
# depth (--target grow; [tune] fixed to the depth given).  One row per run
# appended to OUT (TSV):
#   case spacing_mm variant push_mm status nodes build_s iterations growth_s
#   substeps jmin error
# Cases: default | lobulated | irregular (phantom: lobulation 0.9, plus a
# second component) | patNNNN (BraTS 2013 patNNNN with graphs/armstg.ini,
# data under $DATA, default ../shared/data).
# Variants: NAME or NAME:key=value+key=value (--set options of the grow
# stage), e.g. "shipped log:volumetric=log".
# Usage: sh bench/tled/fine.sh BUILD OUT "default lobulated pat0001" \
#            "6 4 3 2" "shipped log:volumetric=log" [PUSH_MM]
# Backend: TLED (default tled_cuda); each run limited to TLED_FINE_TIMEOUT
# seconds (default 600); FINE_LOGS=DIR keeps each run's log there.
set -u
BUILD=$1 OUT=$2 CASES=$3 SPACINGS=$4 VARIANTS=$5 PUSH=${6:-6}
TO=${TLED_FINE_TIMEOUT:-600}
DATA=${DATA:-../shared/data}
# shellcheck source=bench/pipeline/case_env.sh disable=SC1091
. bench/pipeline/case_env.sh
export ARMSTG_PLUGIN_PATH="$BUILD/plugins" TLED="${TLED:-tled_cuda}"
for c in $CASES; do
    case $c in default|lobulated|irregular|pat[0-9][0-9][0-9][0-9]) ;;
    *) echo "fine.sh: unknown case '$c' (default, lobulated, irregular or patNNNN)" >&2; exit 2 ;;
    esac
done
[ -x "$BUILD/armstg" ] || { echo "fine.sh: no $BUILD/armstg (build first)" >&2; exit 2; }
[ -f "$OUT" ] || printf 'case\tspacing_mm\tvariant\tpush_mm\tstatus\tnodes\tbuild_s\titerations\tgrowth_s\tsubsteps\tjmin\terror\n' >"$OUT"
for c in $CASES; do
    for sp in $SPACINGS; do
        for var in $VARIANTS; do
            vname=${var%%:*}
            sets=""
            case $var in *:*) for kv in $(echo "${var#*:}" | tr '+' ' '); do
                sets="$sets --set grow.$kv"; done ;; esac
            case $c in
            default) g=graphs/demo.ini; cs="" ;;
            lobulated) g=graphs/demo.ini; cs="--set phantom.lobulation=0.9" ;;
            irregular) g=graphs/demo.ini
                cs="--set phantom.lobulation=0.9 --set phantom.two_components=true" ;;
            pat*) g=graphs/armstg.ini; cs=""
                brats_env "${c#pat}" "$DATA" ;;
            *) echo "fine.sh: unknown case '$c'" >&2; exit 2 ;;
            esac
            d=$(mktemp -d /tmp/tledfine.XXXXXX)
            st=ok
            # shellcheck disable=SC2086
            timeout "$TO" "$BUILD/armstg" run "$g" --target grow \
                --set tune.values="$PUSH" --set nodes.spacing="$sp" $cs $sets \
                --out "$d/o" -v >"$d/log" 2>&1 || st=failed
            awk -v c="$c" -v sp="$sp" -v vn="$vname" -v pm="$PUSH" -v st="$st" -v to="$TO" '
                /\[grow@/ && /model: / { for (i = 1; i <= NF; i++) {
                        if ($(i+1) == "nodes") nodes = $i
                        if ($i == "built") bs = $(i+2) } }
                /\[grow@/ && /growth step/ && /iterations/ { for (i = 1; i <= NF; i++) if ($(i+1) ~ /^iterations/) it += $i }
                /\[grow@/ && /growth steps,/ { for (i = 1; i <= NF; i++) if ($(i+1) ~ /^s,?$/) gs = $i }
                /\[grow@/ && /sub-steps/ { ns++ }
                /\[grow@/ && /saturated/ { for (i = 1; i <= NF; i++) if ($i == "at" && $(i+2) == "%") sat = sat (sat == "" ? "" : " ") "saturated at " $(i+1) " %" }
                /\[grow@/ && /min det F/ { for (i = 1; i <= NF; i++) if ($i == "det" && $(i+1) == "F") { v = $(i+2); gsub(/[^-0-9.e]/, "", v); jm = v } }
                /inverted material|failed:|error:|non-finite/ && err == "" { err = $0; gsub(/\t/, " ", err); err = substr(err, 1, 300) }
                END { if (st == "failed" && err == "") err = "failed or timed out (" to " s)"
                      if (st == "ok") err = sat
                      printf "%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%d\t%s\t%s\n", c, sp, vn, pm, st, nodes, bs, it, gs, ns, jm, err }' "$d/log" >>"$OUT"
            tail -1 "$OUT"
            [ "$st" = ok ] || tail -3 "$d/log" | cut -c1-400
            [ -n "${FINE_LOGS:-}" ] && mkdir -p "$FINE_LOGS" && cp "$d/log" "$FINE_LOGS/$c-$sp-$vname-$PUSH.log"
            rm -rf "$d"
        done
    done
done
