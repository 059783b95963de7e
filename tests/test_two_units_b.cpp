// [header] Second translation unit of the two-unit check (see test_two_units.cpp).
#include "smallvcm.hpp"

using LuminanceFunction = float (*)(const smallvcm::Vec3&);
LuminanceFunction LuminanceAddressFromUnitB() { return &smallvcm::Luminance; }
