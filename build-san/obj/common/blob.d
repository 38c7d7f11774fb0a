build-san/obj/common/blob.o: common/blob.c common/blob.h common/log.h
common/blob.h:
common/log.h:
