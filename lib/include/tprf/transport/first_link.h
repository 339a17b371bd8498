#pragma once
/// The former name of transport/second_bounce.h and SecondBounceLight, for sources still written with it.

#include "tprf/transport/second_bounce.h"

namespace tprf {

using FirstLinkLight = SecondBounceLight;

}  // namespace tprf
