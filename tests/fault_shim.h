// Path of the I/O fault injection shim (tests/fault_inject.c), for LD_PRELOAD. Defined in
// test_util.cpp, the one test source that carries this build's paths (ccache then hits the
// fault tests in any clone).
#pragma once
#include <string>

namespace btf::test {
std::string FaultShim();
}
