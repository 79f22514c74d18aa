#!/bin/sh
# Many phantom runs at once on a larger machine (session 7: the 16-core GPU
# host, used for its CPU cores; nothing here uses the GPU).  One run_phantom.sh
# per (seed, variant), all in parallel, one OpenMP thread each (THREADS).
#
#   SEEDS="13 14" VARIANTS="base sphere" sh bench/pipeline/device_phantoms.sh irr|def
#
# variants: base (graphs/armstg.ini), sphere (graphs/spherical.ini), direct
# (graphs/direct_demons.ini).  irr: the irregular phantoms (lobulation 0.9,
# two components); def: the default ones.  The machine has no compiler
# headers or Debian libraries: the build (BUILD, default carry/build: armstg
# and plugins/*.so) and the runtime libraries travel with the checkout
# (debs/*.deb: every package that owns a library `ldd` lists, libcurl's
# dependencies included, not libc6:
#   ldd build/armstg build/plugins/*.so | awk '/=>/{print $3}' | sort -u |
#     xargs -n1 readlink -f | xargs dpkg -S | cut -d: -f1 | sort -u |
#     grep -vx libc6 | (cd debs && xargs apt-get download)
# plus libcom-err2 libkeyutils1 zlib1g, which dpkg -S misses under /lib;
# carry/ and debs/ are listed in .git/info/exclude); BENCH_PREBUILT=1 tells
# lib.sh not to rebuild.  A library still missing there stops the batch
# before any run, naming it (2026-11-23: 80 runs had failed in a second
# each, silently, on libssh2 and libldap).
# EXTRA: more run_phantom.sh options for every run (e.g. "--set
# grow.push_mm=6 --set nodes.spacing=4"); the environment reaches the graphs
# (e.g. PUSH_VALUES, the depths [tune] tries); TAG names the batch, so that two
# batches can run at once.  Output: OUT/all-KIND-VARIANTS[-TAG].txt, every run's phantom.tsv row and
# tune.tsv (the folder's file count is limited), and OUT/KIND-VARIANTS[-TAG].tsv,
# the rows alone (phantom kind and batch first; results/*.tsv).
set -u
die() { echo "device_phantoms.sh: $*" >&2; exit 2; }
[ $# -eq 1 ] || die "usage: SEEDS=\"1 2\" VARIANTS=\"base sphere\" sh $0 irr|def"
case $1 in irr | def) ;; *) die "unknown phantom kind '$1' (irr or def)" ;; esac
[ -n "${SEEDS:-}" ] || die "SEEDS is empty"
[ -n "${VARIANTS:-}" ] || die "VARIANTS is empty"
for v in $VARIANTS; do
	case $v in base | sphere | direct) ;;
	*) die "unknown variant '$v' (base, sphere or direct)" ;; esac
done
[ -x "${BUILD:-carry/build}/armstg" ] || die "no ${BUILD:-carry/build}/armstg (carry the build)"
KIND=$1
. bench/pipeline/carried_libs.sh
carried_libs
export BUILD="${BUILD:-carry/build}" OMP_NUM_THREADS="${THREADS:-1}"
export BENCH_PREBUILT=1
check_libs
# PHANTOM_MORE: more phantom options (e.g. phantom.mass_effect=8)
if [ "$KIND" = irr ]; then
	export PHANTOM_SET="phantom.lobulation=0.9 phantom.two_components=true ${PHANTOM_MORE:-}"
else
	export PHANTOM_SET="${PHANTOM_MORE:-}"
fi
W=/tmp/w${TAG:+-$TAG}
OUT=${OUT:-out/device}
mkdir -p "$W" "$OUT"
for s in $SEEDS; do
	for v in $VARIANTS; do
		(
			case $v in
			base) M=armstg ;;
			sphere) M=sphere ;;
			direct) M=direct ;;
			esac
			# shellcheck disable=SC2086
			METHODS=$M sh bench/pipeline/run_phantom.sh --out "$W/$KIND-$v-$s" \
				--seeds "$s" ${EXTRA:-} >"$W/$KIND-$v-$s.log" 2>&1
		) &
	done
done
wait
for s in $SEEDS; do
	for v in $VARIANTS; do
		d=$KIND-$v-$s
		echo "== $d"
		tail -n +2 "$W/$d/phantom.tsv"
		# a run without its row: the end of its log says why
		[ "$(tail -n +2 "$W/$d/phantom.tsv" 2>/dev/null | wc -l)" -gt 0 ] ||
			{ echo "-- no row; end of $d.log:"; tail -5 "$W/$d.log"; }
		for t in "$W/$d"/ph*/tune.tsv; do
			[ -f "$t" ] && { echo "-- $t"; cat "$t"; }
		done
	done
done >"$OUT/all-$KIND-$(echo "$VARIANTS" | tr ' ' _)${TAG:+-$TAG}.txt"
# the rows alone, as results/*.tsv hold them: phantom kind and batch first
name=$KIND-$(echo "$VARIANTS" | tr ' ' _)${TAG:+-$TAG}
{
	printf 'phantom\tbatch\t'
	head -1 "$W/$KIND-$(echo "$VARIANTS" | cut -d' ' -f1)-$(echo "$SEEDS" | cut -d' ' -f1)/phantom.tsv"
	for s in $SEEDS; do
		for v in $VARIANTS; do
			tail -n +2 "$W/$KIND-$v-$s/phantom.tsv" | sed "s/^/$KIND\t${TAG:--}\t/"
		done
	done
} >"$OUT/$name.tsv"
