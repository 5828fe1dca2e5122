// cgroup_alloc MIB [EXIT_CODE]: allocates MIB MiB, touches every page, then
// exits with EXIT_CODE (default 0). The cgroup harness's own tests run it
// above and below a memory limit.
#include <cstdio>
#include <cstdlib>
#include <cstring>

int main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: cgroup_alloc MIB [EXIT_CODE]\n");
    return 2;
  }
  const long mib = std::strtol(argv[1], nullptr, 10);
  const size_t bytes = size_t(mib) << 20;
  char* p = static_cast<char*>(std::malloc(bytes));
  if (p == nullptr) {
    fprintf(stderr, "cgroup_alloc: malloc(%zu) failed\n", bytes);
    return 3;
  }
  for (size_t i = 0; i < bytes; i += 4096) p[i] = char(i >> 12);
  volatile char sink = p[bytes / 2];
  (void)sink;
  printf("touched %ld MiB\n", mib);
  std::free(p);  // charged already; freed so that LeakSanitizer passes it
  return argc > 2 ? std::atoi(argv[2]) : 0;
}
