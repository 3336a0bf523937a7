// The update path comes first: a background thread (the relinearisation job, its catch-up, the
// batch refinement) lowers its own priority to nice +10 when it starts (Linux nice is per
// thread).
#pragma once

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace arbor {

inline void lowerThisThreadsPriority() {
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10);
}

}  // namespace arbor
