// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The rmw layouts the guard reads (_guard_goals.c: who requested each goal), measured from rmw's
// headers as _fastdds_layout.cpp measures Fast DDS's: setup.py compiles this to assembly only
// (`c++ -S`: nothing is linked or run) wherever it finds rmw's headers (Jazzy's and Kilted's wheels,
// /opt/ros/<distro>), whatever the Fast DDS, and adds the `->NAME VALUE what` lines to
// _fastdds_layout.h. Without them the guard records no requester.
#include <stddef.h>

#include <rmw/types.h>

#define LAYOUT(name, value, what) asm volatile("\n->" #name " %c0 " what : : "i"((long)(value)))

void cft_rmw_layout(void) {
  LAYOUT(RMW_SERVICE_NAME, offsetof(rmw_service_t, service_name), "rmw_service_t::service_name");
  LAYOUT(RMW_INFO_WRITER_GUID,
         offsetof(rmw_service_info_t, request_id) + offsetof(rmw_request_id_t, writer_guid),
         "rmw_service_info_t::request_id.writer_guid (uint8_t[16])");
  LAYOUT(RMW_GUID_SIZE, sizeof(((rmw_request_id_t *)0)->writer_guid), "RMW_GID_STORAGE_SIZE");
}
