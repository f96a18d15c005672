#include "libbtf/core/distributed.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <climits>
#include <cstdlib>

#include "libbtf/core/error.h"

#ifdef BTF_HAVE_MPI
#include <mpi.h>
#endif

namespace btf::dist {
namespace {
int g_rank = 0, g_size = 1;
bool g_started = false;

bool LaunchedAsRank() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(v)) return true;
  return false;
}

#ifdef BTF_HAVE_MPI
constexpr std::size_t kMaxMessage = std::size_t(1) << 30;  // below MPI's int count limit
#endif
}  // namespace

void Init(int* argc, char*** argv) {
  if (g_started || !LaunchedAsRank()) return;
#ifdef BTF_HAVE_MPI
  int provided = 0;
  // OpenMP threads never call MPI: only the main thread communicates.
  MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
  g_started = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
#else
  (void)argc;
  (void)argv;
  ThrowUsage("started by an MPI launcher, but this libbtf was built without MPI (BTF_WITH_MPI=OFF or no "
             "libopenmpi-dev): run it without mpirun, or rebuild with MPI (docs/scaling.md)");
#endif
}

void Finalize() {
#ifdef BTF_HAVE_MPI
  if (g_started) MPI_Finalize();
#endif
  g_started = false;
  g_rank = 0;
  g_size = 1;
}

int Rank() { return g_rank; }
int Size() { return g_size; }

void Send(int to, int tag, const void* data, std::size_t bytes) {
#ifdef BTF_HAVE_MPI
  BTF_CHECK(g_started);
  const auto* p = static_cast<const char*>(data);
  std::size_t done = 0;
  do {  // one message even for 0 bytes, so that sender and receiver always pair
    const int n = static_cast<int>(std::min(kMaxMessage, bytes - done));
    MPI_Send(p + done, n, MPI_BYTE, to, tag, MPI_COMM_WORLD);
    done += static_cast<std::size_t>(n);
  } while (done < bytes);
#else
  (void)to, (void)tag, (void)data, (void)bytes;
  BTF_CHECK(false && "Send without MPI");
#endif
}

void Recv(int from, int tag, void* data, std::size_t bytes) {
#ifdef BTF_HAVE_MPI
  BTF_CHECK(g_started);
  auto* p = static_cast<char*>(data);
  std::size_t done = 0;
  do {  // one message even for 0 bytes, so that sender and receiver always pair
    const int n = static_cast<int>(std::min(kMaxMessage, bytes - done));
    MPI_Recv(p + done, n, MPI_BYTE, from, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    done += static_cast<std::size_t>(n);
  } while (done < bytes);
#else
  (void)from, (void)tag, (void)data, (void)bytes;
  BTF_CHECK(false && "Recv without MPI");
#endif
}

void SendBytes(int to, int tag, const std::vector<std::uint8_t>& bytes) {
  const std::uint64_t n = bytes.size();
  Send(to, tag, &n, sizeof n);
  Send(to, tag, bytes.data(), bytes.size());
}

std::vector<std::uint8_t> RecvBytes(int from, int tag) {
  std::uint64_t n = 0;
  Recv(from, tag, &n, sizeof n);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(n));
  Recv(from, tag, bytes.data(), bytes.size());
  return bytes;
}

void Broadcast(int root, void* data, std::size_t bytes) {
#ifdef BTF_HAVE_MPI
  if (!g_started) return;
  auto* p = static_cast<char*>(data);
  std::size_t done = 0;
  do {
    const int n = static_cast<int>(std::min(kMaxMessage, bytes - done));
    MPI_Bcast(p + done, n, MPI_BYTE, root, MPI_COMM_WORLD);
    done += static_cast<std::size_t>(n);
  } while (done < bytes);
#else
  (void)root, (void)data, (void)bytes;
#endif
}

std::vector<std::uint8_t> BroadcastBytes(int root, std::vector<std::uint8_t> bytes) {
  if (!Distributed()) return bytes;
  std::uint64_t n = bytes.size();
  Broadcast(root, &n, sizeof n);
  bytes.resize(static_cast<std::size_t>(n));
  Broadcast(root, bytes.data(), bytes.size());
  return bytes;
}

void Unpacker::Take(void* dst, std::size_t n) {
  BTF_CHECK(at_ + n <= bytes_.size());
  if (n) std::memcpy(dst, bytes_.data() + at_, n);
  at_ += n;
}

void Unpacker::CheckSize(std::uint64_t got, std::size_t want) { BTF_CHECK(got == want); }

double AllMax(double x) {
#ifdef BTF_HAVE_MPI
  if (g_started) {
    double out = x;
    MPI_Allreduce(&x, &out, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    return out;
  }
#endif
  return x;
}

std::vector<std::vector<std::uint8_t>> AllGather(const std::vector<std::uint8_t>& mine) {
  std::vector<std::vector<std::uint8_t>> all;
  if (!Distributed()) {
    all.push_back(mine);
    return all;
  }
#ifdef BTF_HAVE_MPI
  BTF_CHECK(mine.size() < std::size_t(INT_MAX));
  const int n = static_cast<int>(mine.size());
  std::vector<int> counts(g_size), offsets(g_size);
  MPI_Allgather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, MPI_COMM_WORLD);
  long long total = 0;
  for (int r = 0; r < g_size; ++r) {
    offsets[r] = static_cast<int>(total);
    total += counts[r];
  }
  BTF_CHECK(total < INT_MAX);
  std::vector<std::uint8_t> buffer(static_cast<std::size_t>(total));
  MPI_Allgatherv(mine.data(), n, MPI_BYTE, buffer.data(), counts.data(), offsets.data(), MPI_BYTE, MPI_COMM_WORLD);
  for (int r = 0; r < g_size; ++r) all.emplace_back(buffer.begin() + offsets[r], buffer.begin() + offsets[r] + counts[r]);
#endif
  return all;
}

void AbortJob(int exit_code) {
#ifdef BTF_HAVE_MPI
  if (g_started) MPI_Abort(MPI_COMM_WORLD, exit_code);
#endif
  std::exit(exit_code);
}

std::uint64_t PeakResidentBytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return std::uint64_t(u.ru_maxrss) * 1024;  // Linux reports KiB
}

nlohmann::json GatherRankStats(double seconds) {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  const nlohmann::json mine = {
      {"rank", Rank()}, {"host", std::string(host)}, {"seconds", seconds}, {"peak_rss_bytes", PeakResidentBytes()}};
  const std::string text = mine.dump();
  const auto all = AllGather(std::vector<std::uint8_t>(text.begin(), text.end()));
  nlohmann::json out = nlohmann::json::array();
  for (const auto& bytes : all) out.push_back(nlohmann::json::parse(std::string(bytes.begin(), bytes.end())));
  return out;
}

}  // namespace btf::dist
