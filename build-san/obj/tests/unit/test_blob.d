build-san/obj/tests/unit/test_blob.o: tests/unit/test_blob.c \
 common/blob.h
common/blob.h:
