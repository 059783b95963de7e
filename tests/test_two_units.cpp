// [header] The header is included by every test file without SMALLVCM_IMPLEMENTATION;
// the implementation unit (examples/smallvcm_impl.cpp) is linked once. This file and
// test_two_units_b.cpp check that inline definitions are shared, not duplicated.
#include "smallvcm.hpp"
#include <catch2/catch.hpp>

using LuminanceFunction = float (*)(const smallvcm::Vec3&);
LuminanceFunction LuminanceAddressFromUnitB();

TEST_CASE("The header can be included in several translation units of one program", "[header]") {
    // An inline function has one address in the whole program (ODR); a non-inline
    // definition in the header would have failed to link instead.
    REQUIRE(LuminanceAddressFromUnitB() == &smallvcm::Luminance);
    REQUIRE(smallvcm::Luminance(smallvcm::Vec3(1.f)) == Approx(1.0f).epsilon(1e-5));
}
