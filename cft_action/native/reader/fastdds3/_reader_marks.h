// Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
//
// The client's Fast DDS 3 layer (_reader_marks.cpp, built as its own library, _cftreader_fastdds3):
// what cft_action._rcl asks of it through ctypes.
#ifndef CFT_ACTION_READER_FASTDDS3_READER_MARKS_H_
#define CFT_ACTION_READER_FASTDDS3_READER_MARKS_H_

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

// Appends `mark` to the USER_DATA of `datareader` (an eprosima::fastdds::dds::DataReader *), unless
// it holds it already (DataReader::set_qos: the reader's discovery data is sent again). Returns the
// ReturnCode_t (0: done).
int32_t cft_fastdds3_mark_reader(void *datareader, const char *mark);

// Makes the mark that starts with `prefix` in the USER_DATA of `datareader` `mark` (appended if it
// has none; unchanged if it is `mark` already). Returns the ReturnCode_t (0: done).
int32_t cft_fastdds3_mark_program(void *datareader, const char *prefix, const char *mark);

// Whether the writer `writer_guid` (16 bytes), matched by `datareader`, holds `mark` in its
// USER_DATA: 1 or 0; -1 when it is not matched (or Fast DDS did not answer).
int32_t cft_fastdds3_writer_marked(void *datareader, const uint8_t *writer_guid, const char *mark);

// Of the writers `datareader` matches, how many hold `mark` in their USER_DATA (*marked) and how
// many there are (the return value; -1 when Fast DDS did not answer).
int32_t cft_fastdds3_marked_writers(void *datareader, const char *mark, int32_t *marked);

#ifdef __cplusplus
}
#endif

#endif  // CFT_ACTION_READER_FASTDDS3_READER_MARKS_H_
