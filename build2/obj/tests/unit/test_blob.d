build2/obj/tests/unit/test_blob.o: tests/unit/test_blob.c \
 common/wire/blob.h
common/wire/blob.h:
