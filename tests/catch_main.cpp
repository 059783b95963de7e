// Catch2's main, compiled once (it is slow). The tests run from the tests/ folder, so
// test data is found as data/...
#define CATCH_CONFIG_MAIN
#include <catch2/catch.hpp>
