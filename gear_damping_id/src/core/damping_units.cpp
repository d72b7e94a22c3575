// Placeholder translation unit so the core library always has an object file; the
// conversions themselves are inline in the header.
#include "gear_damping_id/damping_units.hpp"
