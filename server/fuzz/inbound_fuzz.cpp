// libFuzzer target: any bytes a client could send, through the server's
// checks and field reads (walk.hpp). Built with clang when
// -DTACTILE_FUZZ=ON (server/CMakeLists.txt); its corpus is replayed by the
// test suite with any compiler (server/tests/proto/fuzz_corpus_test.cpp).
//   build/fuzz/inbound_fuzz -max_total_time=3600 server/fuzz/corpus proto/vectors
#include <cstddef>
#include <cstdint>

#include "walk.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  volatile uint64_t sink = tactile::fuzz::walk_inbound(data, size);
  (void)sink;
  return 0;
}
