# Writes OUT (a header defining TRBC_GIT_DESCRIBE) from `git describe --always --dirty` of SOURCE_DIR,
# "unknown" outside a git checkout. The file is rewritten only when the text changes, so that an
# unchanged revision recompiles nothing.
execute_process(COMMAND git describe --always --dirty
                WORKING_DIRECTORY "${SOURCE_DIR}"
                OUTPUT_VARIABLE describe
                RESULT_VARIABLE rc
                OUTPUT_STRIP_TRAILING_WHITESPACE
                ERROR_QUIET)
if(NOT rc EQUAL 0 OR describe STREQUAL "")
  set(describe "unknown")
endif()
string(REGEX REPLACE "[^A-Za-z0-9_.+-]" "_" describe "${describe}")
set(text "#pragma once\n#define TRBC_GIT_DESCRIBE \"${describe}\"\n")
if(EXISTS "${OUT}")
  file(READ "${OUT}" old)
else()
  set(old "")
endif()
if(NOT old STREQUAL text)
  file(WRITE "${OUT}" "${text}")
endif()
