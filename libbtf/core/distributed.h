#pragma once
// Distributed runs over MPI (docs/scaling.md). A process started by an MPI launcher (mpirun,
// mpiexec, srun) is one rank of a job; any other process is the only rank of its own job and
// uses no MPI at all, so every tool works as before without a launcher or without an MPI build.
//
// Work is split by round-robin ownership of items (view slots): rank r owns the items i with
// i % Size() == r. Results are combined on rank 0 in item order, so they do not depend on the
// number of ranks. Library code calls only this interface; the tools call Init and Finalize.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace btf::dist {

// Starts MPI when the process was launched as an MPI rank (detected by the environment the
// launchers set: OMPI_COMM_WORLD_SIZE, PMIX_RANK, PMI_RANK); otherwise does nothing. A launched
// process in a build without MPI throws btf::Error (usage): it would otherwise run as N
// unrelated copies. Call once, first thing in main.
void Init(int* argc, char*** argv);
// Ends MPI (no-op when not started). Called by the tools on a normal exit.
void Finalize();

int Rank();  // this process's rank, 0 when not distributed
int Size();  // number of ranks, 1 when not distributed
inline bool Distributed() { return Size() > 1; }
inline bool Owns(int item) { return item % Size() == Rank(); }
// The rank that owns an item.
inline int Owner(int item) { return item % Size(); }

// Point to point, blocking, of raw bytes (any size; split into messages below 2^31 bytes).
void Send(int to, int tag, const void* data, std::size_t bytes);
void Recv(int from, int tag, void* data, std::size_t bytes);
// A byte buffer of any size, its size sent first (pairs with RecvBytes).
void SendBytes(int to, int tag, const std::vector<std::uint8_t>& bytes);
std::vector<std::uint8_t> RecvBytes(int from, int tag);
// Root's bytes on every rank (collective; a no-op outside a distributed run).
void Broadcast(int root, void* data, std::size_t bytes);
// Root's buffer, of any size, on every rank (collective).
std::vector<std::uint8_t> BroadcastBytes(int root, std::vector<std::uint8_t> bytes);
// The maximum of x over all ranks, on every rank (exact).
double AllMax(double x);
// Every rank's bytes, on every rank (index = rank). For small per-rank results (statistics).
std::vector<std::vector<std::uint8_t>> AllGather(const std::vector<std::uint8_t>& mine);

// Every rank's vector of trivially copyable values, concatenated in rank order, on every rank
// (collective). For per-item results of small size (assignments, residuals, statistics).
template <typename T>
std::vector<T> AllGatherConcat(const std::vector<T>& mine) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(mine.data());
  const auto all = AllGather(std::vector<std::uint8_t>(p, p + mine.size() * sizeof(T)));
  std::vector<T> out;
  for (const auto& bytes : all) {
    const std::size_t n = bytes.size() / sizeof(T), at = out.size();
    out.resize(at + n);
    if (n) std::memcpy(out.data() + at, bytes.data(), n * sizeof(T));
  }
  return out;
}

// The ranks one computation runs on, passed down to the code that splits its work, so that
// library code does not ask the process's job itself: World() is this process's MPI job (one
// rank outside a launcher), Single() this process alone whatever the job. On one rank the
// collectives below return their input and nothing is sent.
class Context {
 public:
  static Context World() { return Context(Rank(), Size()); }
  static Context Single() { return Context(0, 1); }
  int rank() const { return rank_; }
  int size() const { return size_; }
  bool distributed() const { return size_ > 1; }
  bool Owns(int item) const { return item % size_ == rank_; }
  int Owner(int item) const { return item % size_; }

  void Send(int to, int tag, const void* data, std::size_t bytes) const { dist::Send(to, tag, data, bytes); }
  void Recv(int from, int tag, void* data, std::size_t bytes) const { dist::Recv(from, tag, data, bytes); }
  void SendBytes(int to, int tag, const std::vector<std::uint8_t>& bytes) const { dist::SendBytes(to, tag, bytes); }
  std::vector<std::uint8_t> RecvBytes(int from, int tag) const { return dist::RecvBytes(from, tag); }
  void Broadcast(int root, void* data, std::size_t bytes) const {
    if (distributed()) dist::Broadcast(root, data, bytes);
  }
  std::vector<std::uint8_t> BroadcastBytes(int root, std::vector<std::uint8_t> bytes) const {
    return distributed() ? dist::BroadcastBytes(root, std::move(bytes)) : bytes;
  }
  double AllMax(double x) const { return distributed() ? dist::AllMax(x) : x; }
  template <typename T>
  std::vector<T> AllGatherConcat(const std::vector<T>& mine) const {
    return distributed() ? dist::AllGatherConcat(mine) : mine;
  }

 private:
  Context(int rank, int size) : rank_(rank), size_(size) {}
  int rank_, size_;
};

// Packs trivially copyable values and vectors of them into bytes, and reads them back in the
// same order (all ranks run the same binary, so no byte-order or layout conversion is needed).
class Packer {
 public:
  template <typename T>
  void Put(const T& x) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&x);
    bytes.insert(bytes.end(), p, p + sizeof(T));
  }
  template <typename T>
  void PutVector(const T* data, std::size_t n) {
    Put(std::uint64_t(n));
    const auto* p = reinterpret_cast<const std::uint8_t*>(data);
    bytes.insert(bytes.end(), p, p + n * sizeof(T));
  }
  template <typename T>
  void PutVector(const std::vector<T>& v) { PutVector(v.data(), v.size()); }
  std::vector<std::uint8_t> bytes;
};

class Unpacker {
 public:
  explicit Unpacker(const std::vector<std::uint8_t>& bytes) : bytes_(bytes) {}
  template <typename T>
  T Get() {
    T x;
    Take(&x, sizeof(T));
    return x;
  }
  template <typename T>
  std::vector<T> GetVector() {
    std::vector<T> v(static_cast<std::size_t>(Get<std::uint64_t>()));
    Take(v.data(), v.size() * sizeof(T));
    return v;
  }
  // Reads a vector of exactly n values into dst.
  template <typename T>
  void GetVectorInto(T* dst, std::size_t n) {
    CheckSize(Get<std::uint64_t>(), n);
    Take(dst, n * sizeof(T));
  }

 private:
  void Take(void* dst, std::size_t n);
  static void CheckSize(std::uint64_t got, std::size_t want);
  const std::vector<std::uint8_t>& bytes_;
  std::size_t at_ = 0;
};

// Ends the whole job with this exit code (MPI_Abort); does not return. Outside a distributed
// run it calls std::exit.
[[noreturn]] void AbortJob(int exit_code);

// This process's peak resident memory (getrusage), bytes.
std::uint64_t PeakResidentBytes();
// Per-rank figures (collective: every rank calls it and gets all of them):
//   [{"rank": r, "host": name, "seconds": s, "peak_rss_bytes": m}, ...].
nlohmann::json GatherRankStats(double seconds);

}  // namespace btf::dist
