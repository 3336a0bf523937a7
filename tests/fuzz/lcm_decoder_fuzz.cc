// One LCM decoder of io/lcm_messages.h (ARBOR_FUZZ_DECODER picks which; tests/fuzz/CMakeLists.txt
// builds one target per decoder): untrusted bytes in, a message or a refusal with its reason
// out, never a crash; what is accepted encodes and decodes again.
#include <cstddef>
#include <cstdint>

#include "arbor_slam/tests/fuzz/fuzz_checks.h"

#define ARBOR_DECODER_EDGE 1
#define ARBOR_DECODER_PRIOR 2
#define ARBOR_DECODER_EDGE_COMMAND 3
#define ARBOR_DECODER_COMMAND 4
#define ARBOR_DECODER_ESTIMATE 5
#define ARBOR_DECODER_STATUS 6
#define ARBOR_DECODER_COVARIANCE 7
#define ARBOR_DECODER_JOURNAL_MARK 8
#define ARBOR_DECODER_RESEND 9

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > (1u << 20)) return 0;
  const int n = static_cast<int>(size);
  using namespace arbor;
#if ARBOR_FUZZ_DECODER == ARBOR_DECODER_EDGE
  fuzz::decodeEdgeBytes(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_PRIOR
  fuzz::decodePriorBytes(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_EDGE_COMMAND
  fuzz::decodeEdgeCommandBytes(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_COMMAND
  fuzz::decodeCommandBytes(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_ESTIMATE
  fuzz::decodeGeneric<estimate_t>(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_STATUS
  fuzz::decodeGeneric<status_t>(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_COVARIANCE
  fuzz::decodeGeneric<covariance_t>(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_JOURNAL_MARK
  fuzz::decodeGeneric<journal_mark_t>(data, n);
#elif ARBOR_FUZZ_DECODER == ARBOR_DECODER_RESEND
  fuzz::decodeResendBytes(data, n);
#else
#error "ARBOR_FUZZ_DECODER names no decoder"
#endif
  return 0;
}
