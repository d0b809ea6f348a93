# trbc_tmcmc_verification: the TMCMC / BASIS verification problems (tmcmc_verification.hpp), one
# definition for trbc_tests_inference and bench_tmcmc_seed_sweep. Included by tests/ and bench/, so
# that either builds without the other; the first inclusion defines the target.
if(NOT TARGET trbc_tmcmc_verification)
  add_library(trbc_tmcmc_verification STATIC ${CMAKE_CURRENT_LIST_DIR}/tmcmc_verification.cpp)
  target_include_directories(trbc_tmcmc_verification PUBLIC ${CMAKE_CURRENT_LIST_DIR})
  target_link_libraries(trbc_tmcmc_verification PUBLIC trbc_inference)
endif()
