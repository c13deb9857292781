// The interfaces are header-only; this file keeps the library non-empty until the
// implementations land.
#include "flatland/drivers/interfaces.hpp"
