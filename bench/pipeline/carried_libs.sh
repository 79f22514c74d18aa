# Sourced by device_bg.sh: a machine without the Debian libraries (the GPU
# host, used for its CPU cores) gets them from debs/*.deb, carried with the
# checkout: every package that owns a library `ldd` lists, libcurl's
# dependencies included, not libc6:
#   ldd build/armstg build/plugins/*.so | awk '/=>/{print $3}' | sort -u |
#     xargs -n1 readlink -f | xargs dpkg -S | cut -d: -f1 | sort -u |
#     grep -vx libc6 | (cd debs && xargs apt-get download)
# plus libcom-err2 libkeyutils1 zlib1g, which dpkg -S misses under /lib;
# carry/ (carry/build = build/ without obj/ and tests/) and debs/ are listed
# in .git/info/exclude.
#
# carried_libs: unpack debs/*.deb once into /tmp/dl (by rename, so batches
#   started together never load a half-written library: SIGBUS) and put it
#   on LD_LIBRARY_PATH before what the caller had there (no debs/: the
#   machine's own libraries, or a folder the caller named).
# check_libs: stop, naming them, when libraries of $BUILD's binaries are
#   missing (2026-11-23: 80 runs had failed in a second each, silently).
carried_libs() {
	for _cl_f in debs/*.deb; do
		if [ -e "$_cl_f" ] && [ ! -d /tmp/dl ]; then
			_cl_t=$(mktemp -d /tmp/dl.XXXXXX)
			for _cl_f in debs/*.deb; do dpkg -x "$_cl_f" "$_cl_t"; done
			mv -T "$_cl_t" /tmp/dl 2>/dev/null || rm -rf "$_cl_t"
		fi
		break
	done
	export LD_LIBRARY_PATH=/tmp/dl/usr/lib/x86_64-linux-gnu:/tmp/dl/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
}

check_libs() {
	_cl_miss=$(ldd "$BUILD/armstg" "$BUILD"/plugins/*.so 2>&1 | awk '/not found/{print $1}' | sort -u | tr '\n' ' ')
	[ -z "$_cl_miss" ] || die "libraries not found on this machine (add their packages to debs/): $_cl_miss"
}
