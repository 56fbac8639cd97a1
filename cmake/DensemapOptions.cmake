# Compiler flags shared by every densemap target (applied through densemap_options).
add_library(densemap_options INTERFACE)
target_compile_options(densemap_options INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wcast-align
  $<$<COMPILE_LANGUAGE:CXX>:-Wnon-virtual-dtor -Woverloaded-virtual>
  # Exactness vs OctoMap depends on the same float operations in the same order: never fuse
  # multiply-adds, never reassociate.
  -ffp-contract=off -fno-fast-math)

if(DENSEMAP_SANITIZER STREQUAL "address")
  target_compile_options(densemap_options INTERFACE -fsanitize=address -fno-omit-frame-pointer)
  target_link_options(densemap_options INTERFACE -fsanitize=address)
elseif(DENSEMAP_SANITIZER STREQUAL "undefined")
  target_compile_options(densemap_options INTERFACE -fsanitize=undefined -fno-sanitize-recover=all)
  target_link_options(densemap_options INTERFACE -fsanitize=undefined)
elseif(DENSEMAP_SANITIZER STREQUAL "thread")
  target_compile_options(densemap_options INTERFACE -fsanitize=thread)
  target_link_options(densemap_options INTERFACE -fsanitize=thread)
elseif(NOT DENSEMAP_SANITIZER STREQUAL "")
  message(FATAL_ERROR "DENSEMAP_SANITIZER must be '', address, undefined or thread; got '${DENSEMAP_SANITIZER}'")
endif()
