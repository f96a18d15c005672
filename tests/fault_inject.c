// I/O fault injection for the fault tests (docs/errors.md, "Faults"): an LD_PRELOAD shim that
// fails the N-th call of one kind of file operation with a chosen errno.
//
//   BTF_FAULT=OP:N:ERRNO   OP is write, read, fsync or rename; N counts from 1; ERRNO is
//                          ENOSPC, EIO, EDQUOT or EROFS. Without it nothing is injected.
//   BTF_FAULT=ACTION:N     an input changing under the reader: at the N-th read, first
//                          "truncate" the file to half its size, "unlink" it, or "replace" it
//                          (rename BTF_FAULT_REPLACEMENT over its name); the read then proceeds.
//   BTF_FAULT_DIR=PREFIX   only files whose path starts with PREFIX count (the test's folder),
//                          so system files (fonts, /proc, /sys) are never touched.
//   BTF_FAULT_COUNTS=FILE  at exit, write "write W\nread R\nfsync F\nrename N\ninjected 0|1\n":
//                          how many calls of each kind were seen (the sweep's range).
//   BTF_FAULT_TRACE=1      print a backtrace to stderr where the fault is injected (debugging).
//
// Intercepted: write, pwrite, pwrite64, writev, fwrite (write); read, pread, pread64, fread
// (read); fsync, fdatasync (fsync); rename, renameat, renameat2 (rename). glibc's stdio flushes
// inside libc are not interposable, so a FILE* write may also fail later, at fflush or fclose:
// the tests accept either.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <execinfo.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

enum { kWrite, kRead, kFsync, kRename, kOps };
static const char* const kNames[kOps] = {"write", "read", "fsync", "rename"};

enum { kFailCall, kTruncate, kUnlink, kReplace };
static int g_op = -1;
static int g_action = kFailCall;
static long g_target = 0;
static int g_errno = EIO;
static const char* g_dir = NULL;
static size_t g_dir_len = 0;
static long g_count[kOps];
static int g_injected = 0;

__attribute__((constructor)) static void Init(void) {
  const char* spec = getenv("BTF_FAULT");
  g_dir = getenv("BTF_FAULT_DIR");
  g_dir_len = g_dir ? strlen(g_dir) : 0;
  if (!spec) return;
  char op[16] = {0}, err[16] = {0};
  long n = 0;
  if (sscanf(spec, "%15[a-z]:%ld:%15[A-Z]", op, &n, err) < 2) return;
  for (int i = 0; i < kOps; ++i)
    if (strcmp(op, kNames[i]) == 0) g_op = i;
  static const char* const kActions[] = {"", "truncate", "unlink", "replace"};
  for (int a = kTruncate; a <= kReplace; ++a)
    if (strcmp(op, kActions[a]) == 0) g_op = kRead, g_action = a;
  g_target = n;
  if (strcmp(err, "ENOSPC") == 0) g_errno = ENOSPC;
  if (strcmp(err, "EDQUOT") == 0) g_errno = EDQUOT;
  if (strcmp(err, "EROFS") == 0) g_errno = EROFS;
}

static int (*RealOpen(void))(const char*, int, ...) {
  static int (*f)(const char*, int, ...) = NULL;
  if (!f) f = (int (*)(const char*, int, ...))dlsym(RTLD_NEXT, "open");
  return f;
}

__attribute__((destructor)) static void Fini(void) {
  const char* path = getenv("BTF_FAULT_COUNTS");
  if (!path) return;
  char buf[256];
  const int len = snprintf(buf, sizeof buf, "write %ld\nread %ld\nfsync %ld\nrename %ld\ninjected %d\n", g_count[kWrite],
                           g_count[kRead], g_count[kFsync], g_count[kRename], g_injected);
  const int fd = RealOpen()(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return;
  ssize_t (*real_write)(int, const void*, size_t) = (ssize_t(*)(int, const void*, size_t))dlsym(RTLD_NEXT, "write");
  if (real_write(fd, buf, (size_t)len) < 0) { /* nothing to do: the test then sees no counts */ }
  close(fd);
}

static int InScope(const char* path) {
  if (!path) return 0;
  if (!g_dir_len) return 1;
  return strncmp(path, g_dir, g_dir_len) == 0;
}

// The path of an open file, or 0 when it cannot be found.
static int FdPath(int fd, char* path, size_t size) {
  char link[64];
  snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
  const ssize_t n = readlink(link, path, size - 1);
  if (n <= 0) return 0;
  path[n] = '\0';
  return 1;
}

static int FdInScope(int fd) {
  struct stat st;
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) return 0;
  if (!g_dir_len) return 1;
  char path[PATH_MAX];
  return FdPath(fd, path, sizeof path) && InScope(path);
}

// The input changes under the reader of `fd` (BTF_FAULT=truncate|unlink|replace).
static void ChangeInput(int fd) {
  char path[PATH_MAX];
  struct stat st;
  if (g_action == kTruncate && fstat(fd, &st) == 0) {
    if (ftruncate(fd, st.st_size / 2) != 0) { /* the test then sees the file unchanged */ }
  } else if (FdPath(fd, path, sizeof path)) {
    if (g_action == kUnlink) unlink(path);
    const char* replacement = getenv("BTF_FAULT_REPLACEMENT");
    int (*real_rename)(const char*, const char*) = (int (*)(const char*, const char*))dlsym(RTLD_NEXT, "rename");
    if (g_action == kReplace && replacement) real_rename(replacement, path);
  }
}

// Counts one call of kind `op` on `fd` (-1: none); nonzero (errno set) when this is the one to
// fail. A change of the input (truncate, unlink, replace) is made here and the call proceeds.
static int Fail(int op, int fd) {
  const long n = __atomic_add_fetch(&g_count[op], 1, __ATOMIC_SEQ_CST);
  if (op != g_op || n != g_target) return 0;
  g_injected = 1;
  if (g_action != kFailCall) {
    if (fd >= 0) ChangeInput(fd);
    return 0;
  }
  if (getenv("BTF_FAULT_TRACE")) {
    void* frames[32];
    backtrace_symbols_fd(frames, backtrace(frames, 32), 2);
  }
  errno = g_errno;
  return 1;
}

#define REAL(name)                        \
  static __typeof__(&name) real_##name = NULL; \
  if (!real_##name) real_##name = (__typeof__(&name))dlsym(RTLD_NEXT, #name)

ssize_t write(int fd, const void* buf, size_t n) {
  REAL(write);
  if (FdInScope(fd) && Fail(kWrite, fd)) return -1;
  return real_write(fd, buf, n);
}

ssize_t pwrite(int fd, const void* buf, size_t n, off_t off) {
  REAL(pwrite);
  if (FdInScope(fd) && Fail(kWrite, fd)) return -1;
  return real_pwrite(fd, buf, n, off);
}

ssize_t pwrite64(int fd, const void* buf, size_t n, off64_t off) {
  REAL(pwrite64);
  if (FdInScope(fd) && Fail(kWrite, fd)) return -1;
  return real_pwrite64(fd, buf, n, off);
}

ssize_t writev(int fd, const struct iovec* iov, int cnt) {
  REAL(writev);
  if (FdInScope(fd) && Fail(kWrite, fd)) return -1;
  return real_writev(fd, iov, cnt);
}

size_t fwrite(const void* buf, size_t size, size_t n, FILE* f) {
  REAL(fwrite);
  if (FdInScope(fileno(f)) && Fail(kWrite, fileno(f))) {
    f->_flags |= _IO_ERR_SEEN;
    return 0;
  }
  return real_fwrite(buf, size, n, f);
}

ssize_t read(int fd, void* buf, size_t n) {
  REAL(read);
  if (FdInScope(fd) && Fail(kRead, fd)) return -1;
  return real_read(fd, buf, n);
}

ssize_t pread(int fd, void* buf, size_t n, off_t off) {
  REAL(pread);
  if (FdInScope(fd) && Fail(kRead, fd)) return -1;
  return real_pread(fd, buf, n, off);
}

ssize_t pread64(int fd, void* buf, size_t n, off64_t off) {
  REAL(pread64);
  if (FdInScope(fd) && Fail(kRead, fd)) return -1;
  return real_pread64(fd, buf, n, off);
}

size_t fread(void* buf, size_t size, size_t n, FILE* f) {
  REAL(fread);
  if (FdInScope(fileno(f)) && Fail(kRead, fileno(f))) {
    f->_flags |= _IO_ERR_SEEN;  // as a failed read leaves the stream: ferror() is true (glibc)
    return 0;
  }
  return real_fread(buf, size, n, f);
}

int fsync(int fd) {
  REAL(fsync);
  if (FdInScope(fd) && Fail(kFsync, fd)) return -1;
  return real_fsync(fd);
}

int fdatasync(int fd) {
  REAL(fdatasync);
  if (FdInScope(fd) && Fail(kFsync, fd)) return -1;
  return real_fdatasync(fd);
}

int rename(const char* from, const char* to) {
  REAL(rename);
  if (InScope(to) && Fail(kRename, -1)) return -1;
  return real_rename(from, to);
}

int renameat(int dfd, const char* from, int tfd, const char* to) {
  REAL(renameat);
  if (InScope(to) && Fail(kRename, -1)) return -1;
  return real_renameat(dfd, from, tfd, to);
}

int renameat2(int dfd, const char* from, int tfd, const char* to, unsigned flags) {
  REAL(renameat2);
  if (InScope(to) && Fail(kRename, -1)) return -1;
  return real_renameat2(dfd, from, tfd, to, flags);
}
