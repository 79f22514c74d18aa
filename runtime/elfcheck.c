/* SPDX-License-Identifier: MIT */
/*
 * The ELF sanity check a plugin file passes before dlopen.
 *
 * The dynamic loader maps a shared object's segments with mmap and trusts
 * the sizes in its headers: a truncated file (a copy cut short, a full
 * disk) maps pages beyond the end of the file, and touching them kills the
 * process with SIGBUS inside dlopen, before any message can be printed.
 * Here the file is read (not mapped) and refused, with a message naming it,
 * unless
 *   - e_ident is an ELF file of this machine's class, byte order and
 *     version, e_type is ET_DYN (a shared object) and e_machine is this
 *     machine's;
 *   - e_ehsize, e_phentsize and e_shentsize are the sizes of the structs;
 *   - the program header table and every segment's file bytes
 *     (p_offset + p_filesz), and the section header table and every
 *     section's file bytes (except SHT_NOBITS), lie inside the file, with
 *     no arithmetic overflow.
 * It does not prove the file is a working plugin (dlopen and the
 * descriptor checks of loader.c do that); it keeps dlopen from crashing.
 */
#include <elf.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <fcntl.h>

#include "rt.h"

#if UINTPTR_MAX == 0xffffffffffffffffu
typedef Elf64_Ehdr elf_ehdr_t;
typedef Elf64_Phdr elf_phdr_t;
typedef Elf64_Shdr elf_shdr_t;
#define ELF_CLASS_HERE ELFCLASS64
#else
typedef Elf32_Ehdr elf_ehdr_t;
typedef Elf32_Phdr elf_phdr_t;
typedef Elf32_Shdr elf_shdr_t;
#define ELF_CLASS_HERE ELFCLASS32
#endif

#if defined(__x86_64__)
#define ELF_MACHINE_HERE EM_X86_64
#elif defined(__aarch64__)
#define ELF_MACHINE_HERE EM_AARCH64
#elif defined(__i386__)
#define ELF_MACHINE_HERE EM_386
#elif defined(__powerpc64__)
#define ELF_MACHINE_HERE EM_PPC64
#else
#define ELF_MACHINE_HERE 0 /* not checked */
#endif

#if __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define ELF_DATA_HERE ELFDATA2LSB
#else
#define ELF_DATA_HERE ELFDATA2MSB
#endif

#define ELF_BAD(...)                                                          \
	do {                                                                  \
		snprintf(err, errsize, __VA_ARGS__);                          \
		rc = ARMSTG_EINVAL;                                           \
		goto out;                                                     \
	} while (0)

/* [off, off + n) inside a file of size sz, without overflow */
static int inside(uint64_t off, uint64_t n, uint64_t sz)
{
	return off <= sz && n <= sz - off;
}

static int read_at(int fd, void *buf, size_t n, uint64_t off)
{
	char *p = buf;
	while (n) {
		ssize_t r = pread(fd, p, n, (off_t)off);
		if (r < 0 && errno == EINTR)
			continue;
		if (r <= 0)
			return -1;
		p += r;
		n -= (size_t)r;
		off += (uint64_t)r;
	}
	return 0;
}

int plugin_check_elf(const char *path, char *err, size_t errsize)
{
	int rc = 0;
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		snprintf(err, errsize, "%s: cannot open: %s", path,
			 strerror(errno));
		return ARMSTG_EIO;
	}
	struct stat sb;
	if (fstat(fd, &sb)) {
		snprintf(err, errsize, "%s: cannot read: %s", path,
			 strerror(errno));
		rc = ARMSTG_EIO;
		goto out;
	}
	if (!S_ISREG(sb.st_mode))
		ELF_BAD("%s: not a regular file", path);
	uint64_t sz = (uint64_t)sb.st_size;
	elf_ehdr_t eh;
	if (sz < sizeof eh || read_at(fd, &eh, sizeof eh, 0))
		ELF_BAD("%s: not a shared object: %llu bytes, shorter than an "
			"ELF header (truncated?)", path,
			(unsigned long long)sz);
	if (memcmp(eh.e_ident, ELFMAG, SELFMAG))
		ELF_BAD("%s: not a shared object (no ELF signature)", path);
	if (eh.e_ident[EI_CLASS] != ELF_CLASS_HERE ||
	    eh.e_ident[EI_DATA] != ELF_DATA_HERE ||
	    eh.e_ident[EI_VERSION] != EV_CURRENT)
		ELF_BAD("%s: an ELF file for another kind of machine (class "
			"%d, byte order %d, version %d)", path,
			eh.e_ident[EI_CLASS], eh.e_ident[EI_DATA],
			eh.e_ident[EI_VERSION]);
	if (eh.e_type != ET_DYN)
		ELF_BAD("%s: not a shared object (ELF type %d)", path,
			eh.e_type);
	if (ELF_MACHINE_HERE && eh.e_machine != ELF_MACHINE_HERE)
		ELF_BAD("%s: built for another processor (ELF machine %d)",
			path, eh.e_machine);
	if (eh.e_ehsize != sizeof eh ||
	    (eh.e_phnum && eh.e_phentsize != sizeof(elf_phdr_t)) ||
	    (eh.e_shnum && eh.e_shentsize != sizeof(elf_shdr_t)))
		ELF_BAD("%s: corrupt ELF header (header or table entry sizes)",
			path);
	if (!eh.e_phnum)
		ELF_BAD("%s: corrupt ELF file: no program headers", path);
	if (!inside(eh.e_phoff, (uint64_t)eh.e_phnum * sizeof(elf_phdr_t), sz))
		ELF_BAD("%s: truncated or corrupt: the program header table "
			"(%u entries at byte %llu) ends beyond the file's %llu "
			"bytes", path, eh.e_phnum,
			(unsigned long long)eh.e_phoff, (unsigned long long)sz);
	for (unsigned i = 0; i < eh.e_phnum; i++) {
		elf_phdr_t ph;
		if (read_at(fd, &ph, sizeof ph,
			    eh.e_phoff + (uint64_t)i * sizeof ph))
			ELF_BAD("%s: cannot read program header %u", path, i);
		if (ph.p_filesz && !inside(ph.p_offset, ph.p_filesz, sz))
			ELF_BAD("%s: truncated or corrupt: segment %u (bytes "
				"%llu to %llu) ends beyond the file's %llu "
				"bytes", path, i,
				(unsigned long long)ph.p_offset,
				(unsigned long long)(ph.p_offset + ph.p_filesz),
				(unsigned long long)sz);
	}
	if (eh.e_shnum || eh.e_shoff) {
		if (!inside(eh.e_shoff,
			    (uint64_t)eh.e_shnum * sizeof(elf_shdr_t), sz))
			ELF_BAD("%s: truncated or corrupt: the section header "
				"table (%u entries at byte %llu) ends beyond "
				"the file's %llu bytes", path, eh.e_shnum,
				(unsigned long long)eh.e_shoff,
				(unsigned long long)sz);
		for (unsigned i = 0; i < eh.e_shnum; i++) {
			elf_shdr_t sh;
			if (read_at(fd, &sh, sizeof sh,
				    eh.e_shoff + (uint64_t)i * sizeof sh))
				ELF_BAD("%s: cannot read section header %u",
					path, i);
			if (sh.sh_type != SHT_NOBITS && sh.sh_size &&
			    !inside(sh.sh_offset, sh.sh_size, sz))
				ELF_BAD("%s: truncated or corrupt: section %u "
					"(bytes %llu to %llu) ends beyond the "
					"file's %llu bytes", path, i,
					(unsigned long long)sh.sh_offset,
					(unsigned long long)(sh.sh_offset +
							     sh.sh_size),
					(unsigned long long)sz);
		}
	}
out:
	close(fd);
	return rc;
}
