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
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace btf::dist {

// True when libbtf was built with MPI (CMake option BTF_WITH_MPI and Open MPI found).
bool Built();

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
// Blocks until every rank has called it.
void Barrier();
// The maximum of x over all ranks, on every rank (exact).
double AllMax(double x);
// Every rank's bytes, on every rank (index = rank). For small per-rank results (statistics).
std::vector<std::vector<std::uint8_t>> AllGather(const std::vector<std::uint8_t>& mine);

// Ends the whole job with this exit code (MPI_Abort); does not return. Outside a distributed
// run it calls std::exit.
[[noreturn]] void AbortJob(int exit_code);

// This process's peak resident memory (getrusage), bytes.
std::uint64_t PeakResidentBytes();
// Per-rank figures (collective: every rank calls it and gets all of them):
//   [{"rank": r, "host": name, "seconds": s, "peak_rss_bytes": m}, ...].
nlohmann::json GatherRankStats(double seconds);

}  // namespace btf::dist
