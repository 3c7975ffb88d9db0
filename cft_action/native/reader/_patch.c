// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// See _patch.h. No object layout is assumed: vtable slots are found by their current value (the
// exported address of the member), PLT slots by the name of their relocation's symbol.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <link.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "_patch.h"

// The protection of the page at addr, from /proc/self/maps (vtables and a bound GOT sit in RELRO:
// read-only).
static int page_protection(uintptr_t addr) {
  FILE *maps = fopen("/proc/self/maps", "r");
  if (maps == NULL) return -1;
  char line[512];
  int prot = -1;
  while (prot < 0 && fgets(line, sizeof line, maps)) {
    unsigned long start, end;
    char perms[5];
    if (sscanf(line, "%lx-%lx %4s", &start, &end, perms) == 3 && addr >= start && addr < end)
      prot = (perms[0] == 'r' ? PROT_READ : 0) | (perms[1] == 'w' ? PROT_WRITE : 0) |
             (perms[2] == 'x' ? PROT_EXEC : 0);
  }
  fclose(maps);
  return prot;
}

static int store_slot(void **slot, void *to) {
  long page = sysconf(_SC_PAGESIZE);
  uintptr_t start = (uintptr_t)slot & ~(uintptr_t)(page - 1);
  int prot = page_protection((uintptr_t)slot);
  if (prot < 0 || mprotect((void *)start, (size_t)page, prot | PROT_WRITE) != 0) return -1;
  __atomic_store_n(slot, to, __ATOMIC_RELEASE);
  if (!(prot & PROT_WRITE)) mprotect((void *)start, (size_t)page, prot);
  return 0;
}

int cft_patch_vtable(void *library, const char *vtable, void *from, void *to) {
  void *table = dlsym(library, vtable);
  Dl_info info;
  const ElfW(Sym) *symbol = NULL;
  if (table == NULL || !dladdr1(table, &info, (void **)&symbol, RTLD_DL_SYMENT) || !symbol)
    return -1;
  void **slots = table;
  size_t count = symbol->st_size / sizeof(void *);
  int patched = 0;
  for (size_t i = 0; i < count; i++) {
    if (slots[i] != from) continue;
    if (store_slot(&slots[i], to) != 0) return -1;
    patched++;
  }
  return patched;
}

struct got_search {
  const char *soname;
  const char *symbol;
  void **slot;
  int found_library;
  uintptr_t begin, end;  // the library's mapped segments: where its lazy PLT stubs are
};

static int find_got_slot(struct dl_phdr_info *info, size_t size, void *data) {
  (void)size;
  struct got_search *s = data;
  const char *name = info->dlpi_name, *slash = name ? strrchr(name, '/') : NULL;
  const char *base = slash ? slash + 1 : name;
  if (base == NULL || strncmp(base, s->soname, strlen(s->soname)) != 0) return 0;
  s->found_library = 1;
  const ElfW(Dyn) *dyn = NULL;
  s->begin = UINTPTR_MAX;
  for (int i = 0; i < info->dlpi_phnum; i++) {
    const ElfW(Phdr) *ph = &info->dlpi_phdr[i];
    if (ph->p_type == PT_DYNAMIC) dyn = (const ElfW(Dyn) *)(info->dlpi_addr + ph->p_vaddr);
    if (ph->p_type != PT_LOAD) continue;
    uintptr_t start = info->dlpi_addr + ph->p_vaddr;
    if (start < s->begin) s->begin = start;
    if (start + ph->p_memsz > s->end) s->end = start + ph->p_memsz;
  }
  if (dyn == NULL) return 1;
  const ElfW(Rela) *jmprel = NULL;
  size_t pltrelsz = 0;
  const ElfW(Sym) *symtab = NULL;
  const char *strtab = NULL;
  for (; dyn->d_tag != DT_NULL; dyn++) {
    // The loader has already relocated these d_ptr entries to run-time addresses.
    if (dyn->d_tag == DT_JMPREL) jmprel = (const ElfW(Rela) *)dyn->d_un.d_ptr;
    else if (dyn->d_tag == DT_PLTRELSZ) pltrelsz = dyn->d_un.d_val;
    else if (dyn->d_tag == DT_SYMTAB) symtab = (const ElfW(Sym) *)dyn->d_un.d_ptr;
    else if (dyn->d_tag == DT_STRTAB) strtab = (const char *)dyn->d_un.d_ptr;
  }
  if (jmprel == NULL || symtab == NULL || strtab == NULL) return 1;
  for (size_t i = 0; i < pltrelsz / sizeof *jmprel; i++) {
    if (ELF64_R_TYPE(jmprel[i].r_info) != R_X86_64_JUMP_SLOT) continue;
    const char *sym = strtab + symtab[ELF64_R_SYM(jmprel[i].r_info)].st_name;
    if (strcmp(sym, s->symbol) == 0) {
      s->slot = (void **)(info->dlpi_addr + jmprel[i].r_offset);
      break;
    }
  }
  return 1;
}

int cft_patch_got(const char *soname, const char *symbol, void *expected, void *to) {
  struct got_search s = {soname, symbol, NULL, 0, 0, 0};
  dl_iterate_phdr(find_got_slot, &s);
  if (s.slot == NULL) return -1;
  void *current = __atomic_load_n(s.slot, __ATOMIC_ACQUIRE);
  if (current == to) return 1;
  // A slot not bound yet (lazy binding) points into the library's own PLT: nobody redirected it.
  bool unbound = (uintptr_t)current >= s.begin && (uintptr_t)current < s.end;
  if (current != expected && !unbound) return 0;
  return store_slot(s.slot, to) == 0 ? 1 : -1;
}

int cft_install_once(struct cft_install *once, int (*install)(struct cft_install *)) {
  pthread_mutex_lock(&once->mutex);
  if (once->status == 1) once->status = install(once);
  int status = once->status;
  pthread_mutex_unlock(&once->mutex);
  return status;
}

int cft_install_fail(struct cft_install *once, int status, const char *what, const char *detail) {
  snprintf(once->error, sizeof once->error, "%s: %s", what, detail ? detail : "");
  return status;
}

void *cft_resolve(struct cft_install *once, const char *soname, const char *const *names,
                  size_t count, void **found, int *status) {
  void *library = dlopen(soname, RTLD_NOW | RTLD_NOLOAD);
  if (library == NULL) {
    *status = cft_install_fail(once, -1, "not loaded", dlerror());
    return NULL;
  }
  for (size_t i = 0; i < count; i++) {
    found[i] = dlsym(library, names[i]);
    if (found[i] == NULL) {
      *status = cft_install_fail(once, -2, "not found", dlerror());
      return NULL;
    }
  }
  return library;
}
