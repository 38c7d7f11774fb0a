build2/obj/common/wire/blob.o: common/wire/blob.c common/wire/blob.h \
 common/base/log.h
common/wire/blob.h:
common/base/log.h:
