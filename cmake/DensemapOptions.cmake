# Compiler flags shared by every densemap target (applied through densemap_options).
add_library(densemap_options INTERFACE)
# Exactness vs OctoMap depends on the same float operations in the same order: never fuse
# multiply-adds, never reassociate.
set(DENSEMAP_FLAGS -Wall -Wextra -Wpedantic -Wshadow -Wcast-align -ffp-contract=off -fno-fast-math)
set(DENSEMAP_CXX_FLAGS -Wnon-virtual-dtor -Woverloaded-virtual)
# Build-only: the installed SDK's densemap::options carries no flags into users' projects.
target_compile_options(densemap_options INTERFACE
  "$<BUILD_INTERFACE:${DENSEMAP_FLAGS}>"
  "$<BUILD_INTERFACE:$<$<COMPILE_LANGUAGE:CXX>:${DENSEMAP_CXX_FLAGS}>>")

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
