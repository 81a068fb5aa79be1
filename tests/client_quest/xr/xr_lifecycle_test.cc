// Session lifecycle of the real m2s_xr_client driven by the simulated runtime's script, and the
// LCM mode against a separate m2s_server in a private network namespace.
#include "xr_client_test_util.h"

namespace m2s::xr_test {
namespace {}  // namespace
}  // namespace m2s::xr_test
